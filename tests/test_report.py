"""report.md, tables and figures from a hand-made metrics table (no training needed)."""

import math

import pytest

from physgnn.report import document as report
from physgnn.report import format as report_format
from physgnn.report import table as report_table
from physgnn.report.sweeps import sweep_axis
from physgnn.report.table import COLUMNS, config_label, read_csv, stat, write_csv

SCENES = ("ood_cubes", "ood_cubes_ramps", "ood_resting_hit", "ood_spaced_drop")


def make_row(run, experiment, overrides, seed, split, traj, mse, diverged_at=None, fps=100.0):
    row = {k: None for k in COLUMNS}
    row.update(
        run=run,
        experiment=experiment,
        overrides=overrides,
        seed=seed,
        split=split,
        trajectory=traj,
        n_spheres=4,
        n_frames=50,
        mse=mse,
        mse20=mse / 2,
        chamfer=mse / 3,
        energy_gain=0.1 * mse,
        depth_sphere=1e-3,
        depth_ground=2e-3,
        depth_static=0.0,
        pct_sphere=10.0,
        pct_ground=5.0,
        pct_static=0.0,
        rotation_error=0.1,
        diverged_at=diverged_at,
        fps=fps,
    )
    return row


def fake_rows():
    """References + an M sweep (2 seeds) + a components ablation where h0 diverges."""
    rows = []
    for ref, mse in (("ground_truth", 0.0), ("static", 50.0), ("gravity_only", 40.0)):
        for t in range(2):
            rows.append(make_row(ref, ref, "", None, "test", f"traj_{t:05d}", mse, fps=None))
        for s in SCENES:
            rows.append(make_row(ref, ref, "", None, "ood", s, mse, fps=None))
    for m in (1, 3, 5):
        for seed in (0, 1):
            run = f"multirun/ablation_M/t/model.network.M={m},seed={seed}"
            for t in range(2):
                rows.append(
                    make_row(
                        run,
                        "ablation_M",
                        f"model.network.M={m} seed={seed}",
                        seed,
                        "test",
                        f"traj_{t:05d}",
                        float(m + seed),
                    )
                )
            for s in SCENES:
                rows.append(
                    make_row(
                        run,
                        "ablation_M",
                        f"model.network.M={m} seed={seed}",
                        seed,
                        "ood",
                        s,
                        float(10 * m + seed),
                    )
                )
    for variant, div in (("baseline", None), ("h0", 7)):
        run = f"multirun/ablation_components/t/+variant={variant},seed=0"
        for s in SCENES:
            rows.append(
                make_row(
                    run,
                    "ablation_components",
                    f"+variant={variant} seed=0",
                    0,
                    "ood",
                    s,
                    3.0,
                    diverged_at=div,
                )
            )
    return rows


def test_config_label_drops_seed_experiment_and_hydra_keys():
    assert (
        config_label("+experiment=ablation_M model.network.M=3 seed=2 hydra.job.num=1")
        == "model.network.M=3"
    )
    assert config_label("seed=0") == "default"
    assert config_label("+variant=h0 seed=1 trainer=gpu") == "variant=h0"
    assert (
        config_label("trainer.max_time=null +callbacks.rollout.max_frames=9 lit.x=1") == "lit.x=1"
    )


def test_sweep_axis_finds_the_varying_key():
    assert sweep_axis(["model.network.M=3 debug=fast", "model.network.M=5 debug=fast"]) == (
        "model.network.M",
        ["3", "5"],
    )


def test_stat_is_mean_and_population_std_of_finite_values():
    rows = [{"mse": 1.0}, {"mse": 3.0}, {"mse": None}, {"mse": math.inf}]
    assert stat(rows, "mse") == (2.0, 1.0, 2)
    assert stat([{"mse": None}], "mse") is None


def test_csv_round_trip_keeps_empty_cells_as_none(tmp_path):
    rows = fake_rows()
    back = read_csv(write_csv(tmp_path / "metrics.csv", rows))
    assert len(back) == len(rows)
    assert back[0]["fps"] is None and back[0]["seed"] is None
    h0 = [r for r in back if "h0" in r["overrides"]]
    assert {r["diverged_at"] for r in h0} == {7}
    assert back[-1]["mse"] == rows[-1]["mse"]
    assert open(tmp_path / "metrics.csv").readline().strip() == ",".join(COLUMNS)


def test_report_from_fake_rows_has_every_section(tmp_path):
    write_csv(tmp_path / "metrics.csv", fake_rows())
    text = report.write_report(tmp_path).read_text()
    for heading in ("Table 1", "trivial baselines", "Table 2", "`ablation_M`", "Runtime"):
        assert heading in text
    assert "diverged at step 7 (4/4)" in text
    assert (tmp_path / "figures" / "sweep_ablation_M.png").stat().st_size > 1000
    assert (tmp_path / "figures" / "fps.png").stat().st_size > 1000
    # the M sweep groups the two seeds: test mse of M=3 is mean of 3, 3, 4, 4 = 3.5 ± 0.5
    line = next(ln for ln in text.splitlines() if ln.startswith("| model.network.M=3 |"))
    assert "| 2 | 3.5 ± 0.5 |" in line
    # every learned M beats static (50) and gravity_only (40) on test; M=5 ood (50, 51) does not
    assert (
        "`ablation_M: model.network.M=1` beats static and gravity_only on mse and chamfer: test ✓"
        in text
    )
    m5 = next(ln for ln in text.splitlines() if "ablation_M: model.network.M=5` beats" in ln)
    assert "ood_cubes ✗" in m5


def test_report_without_learned_runs_says_so(tmp_path):
    rows = [r for r in fake_rows() if r["experiment"] in report_table.REFERENCES]
    write_csv(tmp_path / "metrics.csv", rows)
    text = report.write_report(tmp_path).read_text()
    assert "No trained runs were evaluated." in text
    assert "No `ablation_components` runs" in text
    assert "No learned rollout timed." in text
    # Table 1 carries the Blender reference beside ours
    assert "0.0211 ± 0.0186" in text


@pytest.mark.parametrize(
    "value, text",
    [
        (None, "–"),
        (0.0, "0"),
        (0.5, "0.5"),
        (1e-5, "1.00e-05"),
        (math.nan, "–"),
        (2.5e6, "2.50e+06"),
    ],
)
def test_fmt(value, text):
    assert report_format.fmt(value) == text


def test_report_draws_the_same_work_when_pybullet_rows_are_there(tmp_path):
    rows = fake_rows()
    write_csv(tmp_path / "metrics.csv", rows)
    assert "No pybullet rows" in report.write_report(tmp_path).read_text()
    engine = [
        make_row(
            f"pybullet-{k}",
            "pybullet",
            f"substeps={k}",
            None,
            r["split"],
            r["trajectory"],
            1.0 / k,
            fps=1000.0 / k,
        )
        | {"substeps": k}
        for k in (1, 10)
        for r in rows
        if r["run"] == "ground_truth"
    ]
    write_csv(tmp_path / "metrics.csv", rows + engine)
    text = report.write_report(tmp_path).read_text()
    assert "![pareto_chamfer](figures/pareto_chamfer.png)" in text
    assert "![pareto_mse20](figures/pareto_mse20.png)" in text
    assert (tmp_path / "figures" / "pareto_chamfer.png").stat().st_size > 1000
    line = next(ln for ln in text.splitlines() if ln.startswith("| pybullet-10 |"))
    assert "| 0.05 | 0.0333 |" in line and "| 100 | 10 |" in line  # mse20, chamfer; fps, ms
