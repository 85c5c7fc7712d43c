"""The ablation study (physgnn.ablation): its jobs, registry, measures, verdicts and command."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from scipy import stats
from simdata import trajectory
from torch import nn

import physgnn.ablation.jobs
from physgnn import CONF_DIR
from physgnn.ablation import aggregate, verdicts
from physgnn.ablation.jobs import (
    Config,
    StudyError,
    budget_overrides,
    defaults_fingerprint,
    study_budget,
    study_configs,
    study_jobs,
)
from physgnn.ablation.measure import FIGURES, measure_trajectory
from physgnn.ablation.registry import append_record, done_ids, read_registry
from physgnn.ablation.report import write_study_report
from physgnn.ablation.runner import train_command
from physgnn.ablation.study import run_study, unlisted_keys
from physgnn.cli import compose_config
from physgnn.metrics import trajectory_metrics
from physgnn.models.baselines import GravityOnlySimulator

SWEEPS = [
    "ablation_components",
    "ablation_H",
    "ablation_M",
    "ablation_connectivity",
    "ablation_lambda",
]


@pytest.fixture(scope="module", autouse=True)
def each_training_config_composed_once():
    """A study composes the training config of every sweep point (dozens of Hydra composes),
    and the tests here ask for the same points again and again: each is composed once in this
    module and handed out as a copy."""
    composed = {}

    def once(name, overrides=None):
        key = (name, tuple(overrides or ()))
        if key not in composed:
            composed[key] = compose_config(name, overrides)
        return copy.deepcopy(composed[key])

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(physgnn.ablation.jobs, "compose_config", once)
        yield


def study_cfg(tmp_path, *overrides):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(
            "study",
            overrides=[
                f"paths.outputs={tmp_path}",
                f"registry={tmp_path}/registry.jsonl",
                f"results_dir={tmp_path}/results",
                *overrides,
            ],
        )


def test_the_default_study_adds_the_contact_switches_to_the_reports_sweeps(tmp_path):
    sweeps = list(study_cfg(tmp_path).sweeps)
    assert sweeps == [*SWEEPS, "ablation_contacts"]
    extra = [c.key for c in study_configs(sweeps)][18:]
    assert extra == [
        "model.contacts.contact_passes=0",
        "model.contacts.pair_impulses=False",
        "model.contacts.recent_contact=True",
        "lit.loss.truth_contacts=False",
        "model.inputs.plane_materials=False",
        "model.inputs.contact_features=False",
        "model.inputs.material_features=False",
        "model.contacts.gravity_prior=False",
        "lit.loss.lambda_contact=0",
        "lit.noise.contact_depth=0",
        "model.network.layer_norm=True",
        "model.contacts.contact_memory=True",
        "lit.pushforward.steps=0",
        "lit.pushforward.growth=450 lit.pushforward.steps=4",
    ]


def test_the_five_sweeps_are_18_configurations_the_baseline_shared():
    configs = study_configs(SWEEPS)
    keys = [c.key for c in configs]
    assert len(keys) == len(set(keys)) == 18
    base = configs[0]
    assert base.key == "baseline" and base.overrides == []
    # the default connects by approach, the connectivity sweep's first point
    assert base.points == {
        "ablation_components": "baseline",
        "ablation_H": "0",
        "ablation_M": "5",
        "ablation_connectivity": "approach",
        "ablation_lambda": "0",
    }
    by_key = {c.key: c for c in configs}
    # the variant m1 and the sweep's M = 1 are one configuration, trained once
    assert by_key["model.network.M=1"].points == {"ablation_components": "m1", "ablation_M": "1"}
    assert by_key["lit.loss.lambda_energy=10"].points == {
        "ablation_components": "energy",
        "ablation_lambda": "10",
    }
    # the variant h0 is the default itself: the baseline, its Table 2 row named by an alias
    assert base.aliases == {"ablation_components": ["h0"]}
    assert by_key["model.H=2"].overrides == ["model.H=2"]  # datamodule.H follows, not a key
    assert by_key["model.graph.connectivity=vi"].points == {"ablation_connectivity": "vi"}
    gns = [k for k in keys if "use_surfaces=False" in k]
    assert gns == [
        "model.H=2 model.contacts.contact_passes=0 model.contacts.gravity_prior=False "
        "model.contacts.pair_impulses=False model.contacts.plane_floor=False "
        "model.contacts.plane_newton=False model.contacts.rest_decision=False "
        "model.graph.connectivity=vi model.inputs.boundary_features=True "
        "model.inputs.contact_features=False model.inputs.engine_state=False "
        "model.inputs.mass_ratio=False "
        "model.inputs.material_features=False model.inputs.plane_materials=False "
        "model.inputs.relative_pairs=False model.network.aggregation=sum "
        "model.network.third_law=False model.network.use_surfaces=False"
    ]  # the GNS-style model is the report's (tests/simdata.py, REPORT_MODEL)
    jobs = study_jobs(configs, [0, 1, 2])
    assert len(jobs) == 54
    table2 = [c.key for c in configs if next(iter(c.points)) == "ablation_components"]
    # the baseline's seeds (also Table 2's h0 row), then Table 2's other rows, seed by seed
    assert len(table2) == 7
    assert [(j.config.key, j.seed) for j in jobs[:21]] == [("baseline", s) for s in (0, 1, 2)] + [
        (k, s) for s in (0, 1, 2) for k in table2[1:]
    ]
    assert {j.config.key for j in jobs[21:]} == set(keys) - set(table2)


def test_budget_is_steps_in_whole_epochs():
    cfg = study_cfg("/tmp/unused")
    overrides = budget_overrides(cfg.budget)
    assert "datamodule.pairs_per_epoch=6400" in overrides  # 25 steps of 256 pairs
    assert f"trainer.max_epochs={cfg.budget.steps // 25}" in overrides
    bad = study_cfg("/tmp/unused", "budget.steps=310")
    with pytest.raises(StudyError, match="multiple of budget.steps_per_epoch"):
        budget_overrides(bad.budget)


def test_runs_of_another_default_model_are_not_this_studys(tmp_path, capsys):
    """The budget a record carries names the default training it changed: a record made
    before the default model changed is neither skipped as done nor shown."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        now = compose("train")
        other = compose("train", ["model.network.M=3"])
    assert defaults_fingerprint(now) == defaults_fingerprint(now.copy())
    assert defaults_fingerprint(now) != defaults_fingerprint(other)
    cfg = study_cfg(tmp_path, "dry_run=true", "sweeps=[ablation_M]", "seeds=[0]")  # has M = 5
    budget = study_budget(cfg)
    assert budget["defaults"] == defaults_fingerprint(now) and budget["steps"] == 2250
    old = budget | {"defaults": defaults_fingerprint(other)}
    append_record(tmp_path / "registry.jsonl", rec("baseline", 0, [(1.0, None)]) | {"budget": old})
    run_study(cfg)
    assert "0 in " in capsys.readouterr().out  # the old default's baseline is not done
    append_record(
        tmp_path / "registry.jsonl", rec("baseline", 0, [(1.0, None)]) | {"budget": budget}
    )
    run_study(cfg)
    assert "1 in " in capsys.readouterr().out


def test_registry_keeps_the_latest_line_and_retries_failed_runs(tmp_path):
    path = tmp_path / "r.jsonl"
    budget = {"steps": 3}
    append_record(path, {"key": "a", "seed": 0, "budget": budget, "status": "failed"})
    append_record(path, {"key": "b", "seed": 0, "budget": budget, "status": "diverged"})
    assert done_ids(read_registry(path)) == {("b", 0, '{"steps": 3}')}
    append_record(path, {"key": "a", "seed": 0, "budget": budget, "status": "finished"})
    records = read_registry(path)
    assert [(r["key"], r["status"]) for r in records] == [("a", "finished"), ("b", "diverged")]
    assert len(done_ids(records)) == 2
    assert not done_ids(read_registry(tmp_path / "none.jsonl"))


def rec(key, seed, ood, test=None, share=None):
    """A registry record; ``ood`` = [(mse, diverged_at)] per trajectory."""

    def rows(items):
        return [
            {
                "mse": None if d is not None else m,
                "chamfer": None if d is not None else m,
                "energy_gain": None if d is not None else 0.1 * m,
                "diverged_at": d,
                "energy_error": None if d is not None else abs(0.1 * m - 0.05),
                "max_depth_sphere": None if d is not None else 0.01 * m,
                "energy_gain_truth": 0.05,
                "fps": 10.0,
            }
            for m, d in items
        ]

    logged = {"train/energy_share": share} if share is not None else {}
    return {
        "key": key,
        "seed": seed,
        "status": "finished",
        "budget": {},
        "splits": {"ood": rows(ood), "test": rows(test or ood)},
        "logged": logged,
    }


def test_a_diverged_rollout_makes_its_seed_infinite_never_a_prefix_average():
    records = [
        rec("x", 0, [(1.0, None), (3.0, None)]),
        rec("x", 1, [(0.5, 12), (5.0, None)]),
        rec("x", 2, [(4.0, None), (6.0, None)]),
    ]
    assert aggregate.seed_value(records[1], "ood", "mse") == math.inf
    stat = aggregate.over_seeds(records, "ood", "mse")
    assert (stat.seeds, stat.diverged, stat.finite) == (3, 1, False)
    assert stat.mean == pytest.approx(3.5) and stat.std == pytest.approx(math.sqrt(4.5))
    assert aggregate.divergence(records, "ood") == (1, 6, 12.0)
    assert aggregate.truth_floor(records, "ood") == pytest.approx(0.05)


def test_a_seeds_frames_per_second_is_its_frames_over_its_seconds():
    """100 frames at 10 frames/s and 50 at 50 are 150 frames in 11 s (not the mean rate 30);
    over seeds, mean and sample std."""
    fast, slow = rec("x", 0, [(1.0, None)] * 2), rec("x", 1, [(1.0, None)] * 2)
    for row, (fps, frames) in zip(fast["splits"]["test"], [(10.0, 100), (50.0, 50)], strict=True):
        row.update(fps=fps, frames=frames)
    for row in slow["splits"]["test"]:
        row.update(fps=20.0, frames=100)
    stat = aggregate.mean_fps([fast, slow])
    a, b = 150 / 11, 20.0
    assert stat.seeds == 2 and stat.mean == pytest.approx((a + b) / 2)
    assert stat.std == pytest.approx(abs(a - b) / math.sqrt(2))
    assert aggregate.mean_fps([rec("x", 0, [])]).mean is None


def test_a_report_through_todays_sweeps_names_the_configurations_it_leaves_out():
    """Records of an earlier default whose configuration today's sweeps no longer list are
    named (the page would leave them out); those of another budget are not looked at."""
    budget, other = {"steps": 3}, {"steps": 4}
    records = [
        {"key": k, "seed": 0, "budget": b}
        for k, b in [("baseline", budget), ("model.H=0", budget), ("gone", budget), ("x", other)]
    ]
    configs = [Config("baseline", []), Config("model.network.M=1", [])]
    assert unlisted_keys(records, configs, budget) == ["gone", "model.H=0"]
    assert unlisted_keys(records, configs, other) == ["x"]


def test_verdicts_follow_their_stated_rules():
    base = [rec("baseline", s, [(2.0 + 0.1 * s, None), (2.0, None)]) for s in range(3)]
    many = [rec("m", s, [(1.0, 5), (1.0, 7 if s else None)]) for s in range(3)]  # 5 of 6
    one = [rec("m", s, [(1.0, 5 if s == 0 else None), (1.0, None)]) for s in range(3)]
    stable = [rec("m", s, [(9.0 + s, None), (9.0, None)]) for s in range(3)]
    assert verdicts.diverges(many, base).startswith("reproduced (5/6 diverged vs 0/6, p = ")
    assert verdicts.diverges(one, base).startswith("inconclusive at this budget: 1/6")
    assert verdicts.diverges(stable, base) == "not reproduced: 0/6 OOD rollouts diverged"
    assert verdicts.worse(stable, base).startswith("not comparable")
    # OOD MSE per seed: baseline 2/2.05/2.1, stable 9/9.5/10: Welch's t-test
    d, p = verdicts.difference(stable, base)

    a, b = [9.0, 9.5, 10.0], [2.0, 2.05, 2.1]
    assert d == pytest.approx(np.mean(a) - np.mean(b))
    assert p == pytest.approx(stats.ttest_ind(a, b, equal_var=False).pvalue)
    groups = {"baseline": base, "m": stable, "d": many}
    assert verdicts.best(groups, {"baseline": "baseline", "m1": "m", "h0": "d"}).startswith(
        "reproduced"
    )
    lower = [rec("l", s, [(1.0 + 0.1 * s, None), (1.0, None)]) for s in range(3)]
    close = [rec("c", s, [(2.0 + 0.3 * (s - 1), None), (2.1, None)]) for s in range(3)]
    groups |= {"l": lower, "c": close}
    keys = {"baseline": "baseline", "no_noise": "l"}
    assert verdicts.best(groups, keys).startswith("not reproduced: lower OOD MSE for no_noise")
    keys = {"baseline": "baseline", "m1": "m", "h0": "c"}
    assert verdicts.best(groups, keys).startswith("inconclusive at this budget: no difference")
    one = {"baseline": base[:1], "m": stable[:1]}
    assert verdicts.best(one, {"baseline": "baseline", "m1": "m"}).endswith("too few seeds to test")


class Runaway(nn.Module):
    """Doubles every speed each step: a rollout that must diverge."""

    H = history = 0

    def forward(self, state):
        return 2.0 * state.vel[:, 0] + torch.tensor([0.0, 0.0, 1.0]), state.angvel[:, 0]


def test_measures_are_the_same_for_truth_and_rollout_and_none_after_divergence():
    traj = trajectory(3, frames=40, seed=1)
    fine = measure_trajectory(GravityOnlySimulator(), traj, speed_factor=10.0)
    truth = trajectory_metrics(traj.with_finite_velocities(), traj)
    assert fine["diverged_at"] is None and fine["energy_gain_truth"] == truth["energy_gain"]
    assert all(fine[k] is not None for k in FIGURES) and fine["frames"] == 40
    gone = measure_trajectory(Runaway(), traj, speed_factor=10.0)
    assert 0 < gone["diverged_at"] < 39
    assert all(gone[k] is None for k in FIGURES)  # no figures of the prefix


def test_a_study_job_is_named_in_the_loggers_by_its_changes_and_seed():
    """The study's runs, all of experiment ``study``, told apart in wandb and TensorBoard."""
    spec = {"run_dir": "/r", "seed": 2, "common": ["trainer.max_epochs=1"]}
    names = {
        run_name_of(train_command({**spec, "overrides": o})) for o in ([], ["model.network.M=1"])
    }
    assert names == {"study_seed=2", "study_network.M=1_seed=2"}
    cfg = compose_config("train", ["run_name='study_network.M=1_seed=2'"])
    assert cfg.run_name == "study_network.M=1_seed=2"  # Hydra takes the quoted name


def run_name_of(argv: list[str]) -> str:
    (given,) = [arg for arg in argv if arg.startswith("run_name=")]
    return given.removeprefix("run_name=").strip("'")


def test_dry_run_lists_every_job_and_trains_nothing(tmp_path, capsys):
    cfg = study_cfg(tmp_path, "dry_run=true", "sweeps=[ablation_connectivity]", "seeds=[0,1]")
    run_study(cfg)
    out = capsys.readouterr().out
    assert "4 configurations × 2 seeds = 8 runs" in out and "8 to run" in out
    assert out.count("to run (~") == 8 and "model.graph.connectivity=vmax" in out
    assert not (tmp_path / "study").exists() and not (tmp_path / "registry.jsonl").exists()


def test_report_only_rebuilds_the_page_and_trains_nothing(tmp_path):
    cfg = study_cfg(tmp_path, "report_only=true", "sweeps=[ablation_connectivity]", "seeds=[0]")
    append_record(
        tmp_path / "registry.jsonl",
        rec("baseline", 0, [(1.0, None)]) | {"budget": study_budget(cfg)},
    )
    page = run_study(cfg)
    assert page == tmp_path / "results" / "README.md"
    assert "**1 done**, 0 failed, 3 left" in page.read_text()
    assert not (tmp_path / "study").exists()


@pytest.mark.slow
def test_a_tiny_study_runs_resumes_from_the_registry_and_survives_failures(
    tiny_dataset, tmp_path, capsys
):
    import shutil

    shutil.copytree(tiny_dataset, tmp_path / "data" / "tiny")
    tiny = [
        "sweeps=[ablation_connectivity]",
        "seeds=[0]",
        "preset=tiny",
        "budget.steps=2",
        "budget.steps_per_epoch=1",
        "budget.batch_size=4",
        "horizon=12",
    ]
    broken = study_cfg(tmp_path, *tiny, "budget.extra=['model.network.M=0']")
    with pytest.raises(Exception, match="4 of 4 runs failed"):
        run_study(broken)
    failed = read_registry(tmp_path / "registry.jsonl")
    assert [r["status"] for r in failed] == ["failed"] * 4 and all(r["reason"] for r in failed)

    cfg = study_cfg(tmp_path, *tiny)
    budget = study_budget(cfg)
    append_record(tmp_path / "registry.jsonl", failed[0] | {"budget": budget})  # a failed run
    report = run_study(cfg)  # of this budget: tried again, like the two never run
    records = [r for r in read_registry(tmp_path / "registry.jsonl") if r["budget"] == budget]
    assert sorted(r["key"] for r in records) == [
        "baseline",
        "model.graph.connectivity=epsilon",
        "model.graph.connectivity=vi",
        "model.graph.connectivity=vmax",
    ]
    assert {r["status"] for r in records} == {"finished"}
    assert all(len(r["splits"]["ood"]) == 4 and r["steps"] == 2 for r in records)
    assert all(r["curve"] and r["curve"][0]["step"] >= 1 for r in records)  # learning curve
    assert all(
        r["checkpoint"]["step"] in (1, 2) and r["checkpoint"]["val_loss"] > 0 for r in records
    )  # the measured checkpoint
    base = next(r for r in records if r["key"] == "baseline")  # measured with the stage too
    assert len(base["splits_constraints"]["ood"]) == 4
    assert all("splits_constraints" not in r for r in records if r["key"] != "baseline")
    text = report.read_text()
    assert "4 done" in text and "(report Fig. 17)" in text
    assert (report.parent / "sweep_connectivity.png").stat().st_size > 0

    lines = (tmp_path / "registry.jsonl").read_text().splitlines()
    shutil.rmtree(tmp_path / "study")  # outputs gone: the registry alone decides
    capsys.readouterr()
    run_study(cfg)
    assert "0 to run" in capsys.readouterr().out
    assert (tmp_path / "registry.jsonl").read_text().splitlines() == lines
    assert json.loads(lines[-1])["budget"]["steps"] == 2


@pytest.mark.slow
def test_the_slurm_launcher_runs_the_same_jobs(tiny_dataset, tmp_path):
    """submitit's in-process ``debug`` cluster stands in for SLURM."""
    import shutil

    shutil.copytree(tiny_dataset, tmp_path / "data" / "tiny")
    cfg = study_cfg(
        tmp_path,
        "sweeps=[ablation_connectivity]",
        "seeds=[1]",
        "preset=tiny",
        "budget.steps=1",
        "budget.steps_per_epoch=1",
        "budget.batch_size=4",
        "horizon=8",
        "launcher.name=slurm",
        "launcher.cluster=debug",
        "launcher.poll_s=0.1",
    )
    run_study(cfg)
    records = read_registry(tmp_path / "registry.jsonl")
    assert len(records) == 4 and {r["status"] for r in records} == {"finished"}
    assert {r["seed"] for r in records} == {1}


def test_the_report_is_rebuilt_from_the_registry_alone(tmp_path):
    cfg = study_cfg(tmp_path, "budget.extra=[]")
    configs = study_configs(SWEEPS)
    budget = study_budget(cfg)
    records = []
    for seed in range(3):
        for config in configs:
            gone = 7 if config.key == "model.network.M=1" and seed == 1 else None
            mse = 4.0 + 0.01 * seed if config.key == "baseline" else 5.0 + seed
            lam = float(config.points.get("ablation_lambda", "nan"))
            r = rec(config.key, seed, [(mse, gone), (mse, None)], share=0.01 if lam else 0.0)
            r["logged"] |= {"train/loss": 2.0, "train/loss_energy": 0.01 / (1 + (lam or 0))}
            r |= {
                "budget": budget,
                "overrides": config.overrides,
                "threads": 1,
                "machine": {"cpu": "test cpu", "gpu": None},
                "commit": "abc",
                "date": "2026-01-01 10:00",
                "wall_s": 60.0,
                "checkpoint": {"file": "best-epoch089.ckpt", "step": 2250, "val_loss": 0.5},
                "curve": [
                    {"step": 250 * k, "mse": mse / k, "max_depth": 0.1, "energy_gain": 0.2}
                    for k in (1, 2)
                ],
            }
            if config.key == "baseline":  # the constraint stage halves its OOD MSE
                r["splits_constraints"] = rec("", seed, [(mse / 2, None), (mse / 2, None)])[
                    "splits"
                ]
            records.append(r)
    text = write_study_report(records, configs, cfg).read_text()
    lines = text.splitlines()
    assert "**54 done**, 0 failed, 0 left" in text and "test cpu" in text
    assert "the report trained ≈ 390 000" in text and "3 seeds per configuration" in text
    row = next(line for line in lines if line.startswith("| M = 1 |"))
    assert "**∞ (1/3 seeds diverged)**; others 6 ± 1.41" in row
    assert row.endswith(
        "| 1/6 (median step 7) | +∞: diverged more (p = 1) | diverges | inconclusive at this "
        "budget: 1/6 diverged vs the baseline's 0/6 (p = 0.5) |"
    )
    base = next(line for line in lines if line.startswith("| Baseline |"))
    assert (
        "| 4.01 ± 1.00e-02 |" in base
        and "| best of the table | inconclusive at this budget" in base
    )
    h0 = next(line for line in lines if line.startswith("| H = 0 |"))  # the baseline's records
    assert "| 4.01 ± 1.00e-02 |" in h0
    verdict = "| diverges | not reproduced: 0/6 OOD rollouts diverged |"
    assert f"| 0 (the baseline itself) {verdict}" in h0
    stage = next(line for line in lines if line.startswith("| learned + constraints |"))
    assert "| 2 ± 5.00e-03 |" in stage and "| -2 (p = " in stage
    assert "| 0.5 @ step 2250 |" in text  # the measured checkpoint's validation loss
    assert "**Rules.**" in text and "Welch" in text
    # λ = 10: designed share 10 × 0.01 / (2 + 0.1); the penalty fell 11-fold
    assert "| 10 | 4.8 % | 11× | 1 % |" in text
    for name in ("sweep_H", "sweep_M", "sweep_connectivity", "sweep_lambda", "fps", "curve_H"):
        assert f"({name}.png)" in text and (tmp_path / "results" / f"{name}.png").exists()


def test_the_contact_switches_are_compared_to_the_baseline_on_matched_seeds():
    """Paired differences over the seeds both have, the paired t-test's p, a diverged seed
    named rather than averaged."""
    from physgnn.ablation.switches import paired, switches_section

    configs = study_configs(["ablation_contacts"])
    key = next(c.key for c in configs if c.points.get("ablation_contacts") == "layer_norm")
    base = [rec("baseline", s, [(m, None)]) for s, m in enumerate([4.0, 5.0, 7.0])]
    mine = [rec(key, 0, [(3.0, None)]), rec(key, 1, [(3.5, None)]), rec(key, 2, [(6.0, None)])]
    p = stats.ttest_rel([3.0, 3.5, 6.0], [4.0, 5.0, 7.0]).pvalue
    assert paired(mine, base, "ood", "mse") == f"4.17 (Δ -1.17, p = {p:.2g})"
    # seed 0 alone: its own difference, no test
    assert paired(mine[:1], base, "ood", "mse") == "3 (Δ -1)"
    gone = [mine[0], rec(key, 1, [(3.5, 9)])]
    assert paired(gone, base, "ood", "mse") == "3 (Δ -1); ∞ in 1/2 seeds"
    for r in base + mine:
        r["checkpoint"] = {"step": 2000, "val_score": 2.0}
    text = switches_section({"baseline": base, key: mine}, configs)
    row = next(line for line in text.splitlines() if line.startswith("| with LayerNorm |"))
    assert row.startswith(f"| with LayerNorm | 0, 1, 2 | 4.17 (Δ -1.17, p = {p:.2g}) |")
    assert row.endswith("| 2 @ 2000 |") and "(baseline, 3 seeds: 2 @ 2000)" in text
    assert switches_section({"baseline": base}, configs) == ""


def test_the_learning_curves_draw_mse20_and_whole_rollout_mse_only_for_earlier_records(
    tmp_path, monkeypatch
):
    import physgnn.ablation.figures as figures

    titles = []

    def kept(fig, path):
        titles.append([ax.get_title() for ax in fig.axes])
        figures.plt.close(fig)
        return path

    monkeypatch.setattr(figures, "save_figure", kept)
    point = {"step": 25, "mse": 9.0, "max_depth": 0.1, "energy_gain": 0.2}
    today = [{"curve": [point | {"mse20": 2.0}]}]  # the rollouts stop at the horizon
    earlier = [{"curve": [point]}]  # whole rollouts, no MSE20
    figures.plot_study_curves(tmp_path / "a.png", "t", [("a", today), ("b", earlier)])
    figures.plot_study_curves(tmp_path / "b.png", "t", [("b", earlier)])
    assert titles[0][0] == "validation MSE20 (m²)"
    assert titles[1][0] == "validation rollout MSE (m²)"
