"""physgnn.eval: run discovery, the CLI's errors, and the whole eval on fake run folders."""

import re
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest
import torch
from fakeruns import Falling, eval_cfg, evaluate_fake_runs, fake_outputs, make_run, write_dataset
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from trainkit import SHORT

import physgnn.training.runs
import physgnn.training.train
from physgnn import CONF_DIR
from physgnn import eval as eval_command
from physgnn.data.dataset import read_split
from physgnn.evaluation import evaluate as ev
from physgnn.evaluation import runs as eval_runs
from physgnn.evaluation import video3d
from physgnn.evaluation.data_report import split_summary
from physgnn.evaluation.rerun_log import RerunMissing
from physgnn.evaluation.runs import GIVE_RUNS
from physgnn.report import table as report_table
from physgnn.report.table import read_csv
from physgnn.rollout import rollout

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def outputs(tmp_path):
    return fake_outputs(tmp_path / "outputs")


def test_find_runs_keeps_finished_runs_only(outputs):
    names = [eval_runs.run_name(p, outputs) for p in eval_runs.find_runs(None, outputs)]
    assert names == [
        "multirun/ablation_M/t0/model.network.M=3,seed=1",
        "runs/baseline/2026-01-01_00-00-00",
    ]


def test_find_runs_of_a_multirun_folder_and_of_one_run(outputs):
    multirun = outputs / "multirun" / "ablation_M" / "t0"
    assert eval_runs.find_runs(str(multirun), outputs) == [multirun / "model.network.M=3,seed=1"]
    one = outputs / "runs" / "baseline" / "2026-01-01_00-00-00"
    assert eval_runs.find_runs(str(one), outputs) == [one]


@pytest.mark.parametrize(
    "target, message",
    [
        ("does/not/exist", f"run folder does/not/exist does not exist: {GIVE_RUNS}"),
        ("runs/baseline/2026-01-01_00-00-01", "has not finished"),
        ("runs/nothing", "no finished run"),
    ],
)
def test_find_runs_errors_are_one_line(outputs, target, message):
    (outputs / "runs" / "nothing").mkdir()
    path = target if target.startswith("does") else str(outputs / target)
    with pytest.raises(eval_runs.EvalError, match=re.escape(message)) as err:
        eval_runs.find_runs(path, outputs)
    assert "\n" not in str(err.value)


def test_run_info_joins_overrides_and_reads_seed(outputs):
    run = outputs / "multirun" / "ablation_M" / "t0" / "model.network.M=3,seed=1"
    info = eval_runs.run_info(run, outputs)
    assert (info.experiment, info.overrides, info.seed) == (
        "ablation_M",
        "+experiment=ablation_M model.network.M=3 seed=1",
        1,
    )


def test_dataset_of_reads_the_datamodule_dir():
    cfg = OmegaConf.create(
        {"data": {"dir": "outputs/data/tiny"}, "datamodule": {"data_dir": "${data.dir}"}}
    )
    assert eval_runs.dataset_of(cfg) == Path("outputs/data/tiny")
    with pytest.raises(eval_runs.EvalError, match="names no dataset"):
        eval_runs.dataset_of(OmegaConf.create({"model": {}}))


def test_main_on_a_missing_run_folder_prints_one_line_and_exits_2(tmp_path, capsys):
    cfg = eval_cfg("runs=/no/such/run", f"paths.outputs={tmp_path}")
    with pytest.raises(SystemExit) as exit_:
        eval_command.main.__wrapped__(cfg)  # the Hydra task itself, without the process around it
    assert exit_.value.code == 2
    missing = f"error: run folder /no/such/run does not exist: {GIVE_RUNS}"
    assert capsys.readouterr().err.strip() == missing


@pytest.mark.slow
def test_cli_on_a_missing_run_folder_prints_one_line_and_exits_2(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "physgnn.eval", "runs=/no/such/run", f"paths.outputs={tmp_path}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"error: run folder /no/such/run does not exist: {GIVE_RUNS}"


# ------------------------------------------------------------------ the whole eval, fake runs


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    """metrics.csv and report.md of the fake runs (:func:`evaluate_fake_runs`)."""
    outputs = tmp_path_factory.mktemp("eval") / "outputs"
    path = evaluate_fake_runs(outputs, "video_frames=5", "save_rollouts=true")
    return outputs, read_csv(outputs / "report" / "metrics.csv"), path.read_text()


def test_save_rollouts_writes_each_learned_run_in_the_dataset_schema(evaluated):
    outputs, rows, _ = evaluated
    saved = outputs / "report" / "rollouts" / "runs" / "baseline" / "2026-01-01_00-00-00"
    truth = read_split(outputs / "data" / "hand" / "test.h5")
    preds = read_split(saved / "test.h5")
    assert [p.name for p in preds] == [t.name for t in truth]
    expected = rollout(Falling(), truth)
    for pred, want in zip(preds, expected, strict=True):
        torch.testing.assert_close(torch.as_tensor(pred.pos), torch.as_tensor(want.pos))
        assert pred.attrs["run"] == "runs/baseline/2026-01-01_00-00-00"
        assert int(pred.attrs["diverged_at"]) == -1 and int(pred.attrs["start"]) == want.start
    diverging = outputs / "report" / "rollouts" / "multirun" / "ablation_M" / "t0"
    bad = read_split(diverging / "model.network.M=3,seed=1" / "ood.h5")
    assert all(int(p.attrs["diverged_at"]) == p.n_frames for p in bad)
    assert not (outputs / "report" / "rollouts" / "ground_truth").exists()


def test_eval_writes_one_row_per_run_split_and_trajectory(evaluated):
    outputs, rows, _ = evaluated
    runs = [r["run"] for r in rows]
    # 3 references and 2 runs x (2 test + 2 ood) + OOD (c) again with sleeping on, and pybullet
    # at each substep count on the same 4 trajectories (both runs have H = 1: one start)
    substeps = list(eval_cfg().pybullet.substeps)
    assert len(rows) == 5 * 4 + 1 + 4 * len(substeps)
    assert [r["substeps"] for r in rows if r["experiment"] == "pybullet"] == [
        k for k in substeps for _ in range(4)
    ]
    assert runs.count("pybullet-1") == 4 and rows[0]["substeps"] is None
    assert runs.count("ground_truth") == runs.count("static") == runs.count("gravity_only") == 4
    assert runs.count("runs/baseline/2026-01-01_00-00-00+sleeping") == 1
    assert {r["trajectory"] for r in rows if r["split"] == "ood"} == {
        "ood_cubes",
        report_table.SLEEP_SCENE,
    }


def test_ground_truth_and_static_rows_match_hand_computed_values(evaluated):
    outputs, rows, _ = evaluated
    data = read_split(outputs / "data" / "hand" / "test.h5")
    for traj in data:
        gt = next(r for r in rows if r["run"] == "ground_truth" and r["trajectory"] == traj.name)
        assert gt["mse"] == 0.0 and gt["chamfer"] == 0.0 and gt["diverged_at"] is None
        static = next(r for r in rows if r["run"] == "static" and r["trajectory"] == traj.name)
        pos = traj.pos.astype(np.float64)
        held = ((pos - pos[0]) ** 2).sum(-1).mean()  # static holds frame 0 (H = 0)
        assert static["mse"] == pytest.approx(held, rel=1e-5)
        assert static["n_frames"] == 12 and static["fps"] > 0


def test_diverged_run_is_flagged_with_finite_metrics(evaluated):
    _, rows, text = evaluated
    bad = [r for r in rows if r["experiment"] == "ablation_M"]
    assert all(r["diverged_at"] is not None and 2 <= r["diverged_at"] < 12 for r in bad)
    assert all(r["n_frames"] == r["diverged_at"] and np.isfinite(r["mse"]) for r in bad)
    first = min(r["diverged_at"] for r in bad)
    assert f"diverged at step {first}" in text


def test_report_links_figures_and_one_video_per_ood_scene(evaluated):
    outputs, _, text = evaluated
    report_dir = outputs / "report"
    for scene in ("ood_cubes", report_table.SLEEP_SCENE):
        gif = report_dir / "videos" / f"{scene}.gif"
        assert len(imageio.mimread(gif)) == 5
        with imageio.get_reader(gif.with_suffix(".mp4")) as mp4:
            assert mp4.count_frames() == 5
        assert f"[{scene}](videos/{scene}.gif) ([MP4](videos/{scene}.mp4))" in text
    assert (report_dir / "figures" / "energy_ood.png").stat().st_size > 1000
    assert "![energy](figures/energy_ood.png)" in text
    assert "with sleeping off and on" in text and "| on |" in text
    # the multirun run that never finished is listed, not evaluated
    assert "`multirun/ablation_M/t0/model.network.M=5,seed=1`: status diverged" in text


def test_ground_truth_rows_equal_the_data_report_measured_as_rollouts_are(evaluated):
    outputs, rows, _ = evaluated
    for split in ("test", "ood"):
        trajs = read_split(outputs / "data" / "hand" / f"{split}.h5")
        expected = split_summary(trajs, velocities="finite")  # as a rollout's velocities
        gt = [r for r in rows if r["run"] == "ground_truth" and r["split"] == split]
        for key, value in expected.items():
            mean, std, n = report_table.stat(gt, key)
            assert n == len(trajs)
            assert mean == pytest.approx(value["mean"], rel=1e-9, abs=1e-12), key
            assert std == pytest.approx(value["std"], rel=1e-6, abs=1e-12), key


# ------------------------------------------------------------------ a real tiny run

TINY_TRAIN = [
    "data=tiny",
    *SHORT,
    "++callbacks.rollout._target_=physgnn.training.callbacks.RolloutCallback",
    "++callbacks.rollout.every_n_epochs=1",
    "++callbacks.rollout.n_val_trajectories=1",
    "++callbacks.rollout.max_frames=8",
    "++callbacks.rollout.ood=true",
]


@pytest.mark.slow
def test_tiny_run_logs_rollouts_then_make_eval_reports_it(tiny_dataset, tmp_path):
    outputs = tmp_path / "outputs"
    run_dir = outputs / "runs" / "baseline" / "t0"
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        cfg = compose("train", [*TINY_TRAIN, f"run_dir={run_dir}", f"data.dir={tiny_dataset}"])
    info = physgnn.training.train.train(cfg)
    # the callback logged through pl_module.log: the CSV logger has its columns
    header = (run_dir / "csv" / "version_0" / "metrics.csv").read_text().splitlines()[0]
    for key in (
        "val/rollout_mse",
        "val/chamfer",
        "ood/energy_gain",
        "ood/pct_sphere",
        "rollout/fps",
    ):
        assert key in header.split(",")
    assert info["status"] == "finished"

    path = ev.evaluate(eval_cfg(f"paths.outputs={outputs}", "video_frames=3"))
    rows = read_csv(outputs / "report" / "metrics.csv")
    learned = [r for r in rows if r["run"] == "runs/baseline/t0"]
    assert [r["split"] for r in learned] == ["test"] + ["ood"] * 4
    assert all(r["n_frames"] == 20 or r["diverged_at"] is not None for r in learned)
    text = path.read_text()
    assert "| baseline: default |" in text and "### `baseline`" in text
    assert len(list((outputs / "report" / "videos").glob("*.gif"))) == 4
    assert len(list((outputs / "report" / "videos").glob("*.mp4"))) == 4

    # with the constraint stage: its variant in the tables, and filmed beside the pure run
    report = outputs / "report_stage"
    ev.evaluate(
        eval_cfg(
            f"paths.outputs={outputs}",
            "video_frames=3",
            "rollout.constraints=2",
            f"report_dir={report}",
        )
    )
    runs = {r["run"] for r in read_csv(report / "metrics.csv")}
    assert {"runs/baseline/t0", "runs/baseline/t0 + constraints"} <= runs
    frame = imageio.imread(report / "videos" / "ood_cubes_frame.png")
    assert frame.shape[1] == 3 * video3d.WIDTH  # truth, pure, + constraints


def test_eval_of_a_dataset_alone_reports_the_references(tmp_path):
    data = write_dataset(tmp_path / "data")
    out = tmp_path / "empty"
    with pytest.raises(eval_runs.EvalError, match="no finished run under"):
        ev.evaluate(eval_cfg(f"paths.outputs={out}"))
    text = ev.evaluate(eval_cfg(f"paths.outputs={out}", f"dataset={data}")).read_text()
    assert "`ground_truth`: 2 test and 2 OOD trajectories." in text
    assert "No trained runs were evaluated." in text and "No videos." in text
    rows = read_csv(out / "report" / "metrics.csv")
    assert sorted({r["run"] for r in rows}) == ["gravity_only", "ground_truth", "static"]


def test_a_run_whose_dataset_is_gone_is_one_clear_error(tmp_path, monkeypatch):
    out = tmp_path / "outputs"
    make_run(out / "runs" / "baseline" / "t0")
    cfg = OmegaConf.create({"datamodule": {"data_dir": str(tmp_path / "gone")}})
    monkeypatch.setattr(physgnn.training.runs, "load_run", lambda run_dir: (Falling(), cfg, {}))
    with pytest.raises(eval_runs.EvalError, match=r"dataset folder .*gone does not exist"):
        ev.evaluate(eval_cfg(f"paths.outputs={out}"))


def test_truncated_runs_are_evaluated_and_named_so(tmp_path):
    outputs = tmp_path / "outputs"
    for name, status in (("a", "finished"), ("b", "truncated"), ("c", "interrupted")):
        physgnn.training.runs.write_run_json(outputs / "runs" / name, {"status": status})
    runs = eval_runs.find_runs(None, outputs)
    assert [p.name for p in runs] == ["a", "b"]
    names = [eval_runs.run_info(p, outputs).name for p in runs]
    assert names == ["runs/a", "runs/b (truncated)"]


def test_eval_rerun_without_the_extra_fails_before_any_rollout(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun raises ImportError
    with pytest.raises(RerunMissing, match=r"needs the optional rerun-sdk: pip install"):
        ev.evaluate(eval_cfg(f"paths.outputs={tmp_path / 'nothing'}", "rerun=true"))


def test_eval_rerun_records_each_ood_scene_of_the_filmed_run(tmp_path):
    pytest.importorskip("rerun")
    outputs = tmp_path / "outputs"
    evaluate_fake_runs(outputs, "videos=false", "rerun=true", "sleeping_compare=false")
    videos = outputs / "report" / "videos"
    names = sorted(p.name for p in videos.iterdir())
    assert names == sorted(f"{s}.rrd" for s in ("ood_cubes", report_table.SLEEP_SCENE))
