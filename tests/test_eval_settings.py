"""``make eval``'s learned settings: every trained run again at its own knobs, the rows
``<run> · <setting>`` of metrics.csv (physgnn.evaluation.learned_settings), points of the
same-work table and front (physgnn.report.same_work)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from physgnn import CONF_DIR
from physgnn.data.dataset import read_split
from physgnn.errors import ConfigError
from physgnn.evaluation import evaluate as ev
from physgnn.evaluation import learned_settings as ls
from physgnn.evaluation.rollouts import Collected, roll_all, rollout_threads
from physgnn.evaluation.runs import RunInfo
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.report import same_work
from physgnn.report.table import COLUMNS, read_csv
from physgnn.training.runs import load_run


def row(run, mse20, fps, split="test", setting=None, experiment="baseline", substeps=None):
    r = dict.fromkeys(COLUMNS)
    r.update(run=run, experiment=experiment, overrides="", split=split, trajectory="t0")
    r.update(mse20=mse20, chamfer=mse20, fps=fps, setting=setting, substeps=substeps)
    return r


def engine(k, mse20, fps, split="test"):
    return row(f"pybullet-{k}", mse20, fps, split, experiment="pybullet", substeps=k)


def test_the_front_is_drawn_over_the_runs_their_settings_and_pybullet():
    # ms per frame = 1000 / fps. pybullet-1: 1 ms at 1.0, pybullet-5: 5 ms at 0.1.
    # the run as trained: 4 ms at 0.5, dominated by passes0 (2 ms at 0.4) -> off the front;
    # constraints5: 10 ms at 0.3, dominated by pybullet-5 -> off
    rows = [
        row("runs/a", 0.5, 250.0),
        row("runs/a · passes0", 0.4, 500.0, setting="passes0"),
        row("runs/a · constraints5", 0.3, 100.0, setting="constraints5"),
        engine(1, 1.0, 1000.0),
        engine(5, 0.1, 200.0),
        # ood: the run as trained is best, no setting on the front
        row("runs/a", 0.05, 1000.0, "ood"),
        row("runs/a · passes0", 0.4, 500.0, "ood", "passes0"),
        engine(1, 1.0, 1000.0, "ood"),
    ]
    pts = same_work.points(rows, "test", "mse20")
    assert [(p.label, p.ms_per_frame, p.error, p.kind) for p in pts] == [
        ("baseline: default", 4.0, 0.5, "learned"),
        ("baseline: default · constraints5", 10.0, 0.3, same_work.SETTING),
        ("baseline: default · passes0", 2.0, 0.4, same_work.SETTING),
        ("pybullet-1", 1.0, 1.0, "pybullet"),
        ("pybullet-5", 5.0, 0.1, "pybullet"),
    ]
    assert [p.label for p in same_work.front(pts)] == [
        "pybullet-1",
        "baseline: default · passes0",
        "pybullet-5",
    ]
    test = same_work.settings_on_front(rows, "test")
    assert test == "Learned settings on test's mse20 front: `baseline: default · passes0`."
    assert same_work.settings_on_front(rows, "ood") == "No learned setting is on ood's mse20 front."
    assert same_work.settings_on_front(rows[3:5], "test") == ""  # no setting's point
    text = same_work.section(rows)
    assert text.count("| baseline: default · passes0 |") == 2 and test in text
    table = same_work.split_table(rows, "test").splitlines()[2:]
    marks = {ln.split(" | ")[0][2:]: ln.split(" | ")[-2] for ln in table}
    assert marks["baseline: default · passes0"] == "✓" and marks["baseline: default"] == ""


def test_a_bad_learned_setting_is_one_line_naming_its_key():
    assert ls.check_settings(None) == ls.check_settings(OmegaConf.create({})) == {}
    good = OmegaConf.create({"p0": {"contact_passes": 0}, "own": None, "c": {"constraints": 5}})
    assert ls.check_settings(good) == {
        "p0": {"contact_passes": 0},
        "own": {},
        "c": {"constraints": 5},
    }
    cases = [
        (
            {"p0": {"contact_passes": -1}},
            "learned_settings.p0.contact_passes must be a whole number >= 0 or null (graph "
            "rebuilds within a frame), got -1 (e.g. learned_settings.p0.contact_passes=0)",
        ),
        ({"t": {"threads": 0}}, "learned_settings.t.threads must be a whole number >= 1 or null"),
        (
            {"c": {"compile": "yes"}},
            "learned_settings.c.compile must be true or false or null, got 'yes'",
        ),
        (
            {"x": {"passes": 1}},
            "learned_settings.x: unknown knob passes "
            "(knobs: contact_passes, constraints, compile, threads)",
        ),
        ({"x": 3}, "learned_settings.x must be a mapping of knobs"),
        (5, "learned_settings must be null or a mapping of setting name to knobs, got 5"),
    ]
    for value, message in cases:
        with pytest.raises(ConfigError, match=f"^{re.escape(message)}") as info:
            ls.check_settings(OmegaConf.create({"v": value}).v)
        assert "\n" not in str(info.value)


def _tiny(tiny_dataset: Path) -> dict:
    return {tiny_dataset: {s: read_split(tiny_dataset / f"{s}.h5") for s in ("test", "ood")}}


def test_a_setting_rolls_out_from_the_runs_starts_and_as_trained_scores_as_the_run(
    tiny_run, tiny_dataset, one_thread
):
    sim = load_run(tiny_run)[0].eval()
    own = int(sim.contacts.contact_passes)
    run = RunInfo("runs/t", "baseline", run_dir=tiny_run, dataset=tiny_dataset, simulator=sim)
    data = _tiny(tiny_dataset)
    settings = {"own": {"contact_passes": own}, "passes0": {"contact_passes": 0, "threads": 2}}
    jobs = ls.setting_jobs([run], settings)
    assert [j.name for j in jobs] == ["runs/t · own", "runs/t · passes0"]
    assert [j.extra["knobs"] for j in jobs] == [
        {"contact_passes": own, "constraints": 0, "compile": False, "threads": 1},
        {"contact_passes": 0, "constraints": 0, "compile": False, "threads": 2},
    ]
    assert jobs[1].simulator.contacts.contact_passes == 0 != own == sim.contacts.contact_passes
    [stage] = ls.setting_jobs([run], {"c": {"constraints": 2}})
    assert isinstance(stage.simulator, ConstrainedSimulator) and stage.simulator.iterations == 2
    trained = roll_all([run], data, Collected(set(), [], 0.0)).rows
    rows = ls.setting_rows(jobs, data, 0.0, None, batch_scenes=True)
    assert torch.get_num_threads() == 1  # passes0's two threads only while it ran
    assert {r["threads"] for r in trained} == {1}
    assert [r["threads"] for r in rows] == [1] * len(trained) + [2] * len(trained)
    assert [r["setting"] for r in rows] == ["own"] * len(trained) + ["passes0"] * len(trained)
    for name in ("own", "passes0"):
        mine = [r for r in rows if r["setting"] == name]
        where = [(r["split"], r["trajectory"], r["n_frames"]) for r in mine]
        assert where == [(r["split"], r["trajectory"], r["n_frames"]) for r in trained]
        assert {r["run"] for r in mine} == {f"runs/t · {name}"}
    as_trained = [r["mse"] for r in rows if r["setting"] == "own"]
    assert as_trained == [r["mse"] for r in trained]  # bit for bit: the same rollouts
    assert [r["mse"] for r in rows if r["setting"] == "passes0"] != as_trained


def test_make_eval_puts_the_settings_on_the_same_work_table(tiny_run, tiny_dataset, tmp_path):
    overrides = [
        f"runs={tiny_run}",
        f"dataset={tiny_dataset}",
        f"paths.outputs={tmp_path}",
        f"report_dir={tmp_path / 'report'}",
        *("videos=false", "stability=false", "invariance=null", "onestep=null"),
        *("sleeping_compare=false", "pybullet.substeps=[1]", "freefall=null", "bounce=null"),
        "learned_settings=null",  # then a list of its own, not merged into the default one
        "learned_settings={as_trained: {}, passes0: {contact_passes: 0, threads: 2}}",
    ]
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        cfg = compose("eval", overrides)
    text = ev.evaluate(cfg).read_text()
    rows = read_csv(tmp_path / "report" / "metrics.csv")
    run = [r for r in rows if not r["setting"] and r["experiment"] == "baseline"]
    for name in ("as_trained", "passes0"):
        mine = [r for r in rows if r["setting"] == name]
        assert [r["trajectory"] for r in mine] == [r["trajectory"] for r in run]
        assert all(r["run"].endswith(f" · {name}") for r in mine)
    same = [r["mse"] for r in rows if r["setting"] == "as_trained"]
    assert same == [r["mse"] for r in run]
    labels = list(same_work.setting_groups(rows))  # "baseline: <its overrides> · <setting>"
    assert [label.rsplit(" · ", 1)[1] for label in labels] == ["as_trained", "passes0"]
    for label in labels:  # in the same-work tables only, test and OOD
        assert text.count(f"| {label} |") == 2
    # every learned rollout on rollout.threads (1) unless its setting names its own
    threads = {
        r["run"].split(" · ")[-1]: r["threads"] for r in rows if r["experiment"] != "pybullet"
    }
    assert {k: v for k, v in threads.items() if k in ("as_trained", "passes0")} == {
        "as_trained": 1,
        "passes0": 2,
    }
    assert {r["threads"] for r in run} == {1}
    # pybullet in as many processes as the learned rollouts' threads (rollout.threads: 1)
    assert {r["threads"] for r in rows if r["experiment"] == "pybullet"} == {1}
    assert "| threads |" in text
    assert "No free-fall measurements" in text and "No bounce measurements" in text


def test_where_no_learned_point_is_on_the_front_the_report_says_how_far_the_nearest_is():
    # the run: 4 ms at 0.5; pybullet-5 (2 ms at 0.1) beats it on both, pybullet-1 is 1 ms at 1.0:
    # at its error it needs more than 4 / 2 = 2× its frames/s, at its cost an error below 0.1
    rows = [row("runs/a", 0.5, 250.0), engine(1, 1.0, 1000.0), engine(5, 0.1, 500.0)]
    pts = same_work.points(rows, "test", "mse20")
    (speed, faster), (accuracy, better) = same_work.lacks(pts, pts[0])
    assert (speed, faster.label, accuracy, better.label) == (2.0, "pybullet-5", 5.0, "pybullet-5")
    assert same_work.distance_to_front(rows, "test") == (
        "Nearest to test's mse20 front: `baseline: default` (mse20 0.5 at 250 frames/s) needs "
        "more than 2× its frames/s (`pybullet-5`: 0.1 at 500); `baseline: default` needs, at its "
        "frames/s, an mse20 below 0.1, 5× lower than its 0.5 (`pybullet-5`)."
    )
    assert same_work.distance_to_front(rows, "test") in same_work.section(rows)
    on_it = [row("runs/a", 0.05, 250.0), *rows[1:]]  # the most accurate point: on the front
    assert same_work.distance_to_front(on_it, "test") == ""
    # the truth's own setting: exact and faster than the run, so no error at its cost will do
    exact = [*rows, engine(40, 0.0, 300.0)]
    assert same_work.distance_to_front(exact, "test").endswith(
        "; no mse20 puts `baseline: default` on it at its frames/s (`pybullet-40` is exact and "
        "at least as fast)."
    )


def test_the_learned_rollouts_run_on_the_evals_threads_and_their_rows_say_so(
    tiny_run, tiny_dataset, one_thread
):
    sim = load_run(tiny_run)[0].eval()
    run = RunInfo("runs/t", "baseline", run_dir=tiny_run, dataset=tiny_dataset, simulator=sim)
    truth = RunInfo("ground_truth", "ground_truth", dataset=tiny_dataset)
    data = _tiny(tiny_dataset)
    rows = roll_all([truth, run], data, Collected(set(), [], 0.0), threads=2).rows
    assert torch.get_num_threads() == 1  # two threads only while the run rolled out
    assert {r["threads"] for r in rows if r["run"] == "runs/t"} == {2}
    assert {r["threads"] for r in rows if r["run"] == "ground_truth"} == {None}
    assert same_work.threads_cell(rows) == "2"
    assert same_work.threads_cell([row("pybullet-1", 1.0, 10.0)]) == "–"  # a csv before the column


@pytest.mark.parametrize("value", [0, 1.5, "two"])
def test_rollout_threads_is_refused_in_one_line_naming_the_key(value):
    cfg = OmegaConf.create({"rollout": {"threads": value}})
    with pytest.raises(ConfigError, match=r"^rollout\.threads") as caught:
        rollout_threads(cfg)
    assert "\n" not in str(caught.value)
    assert rollout_threads(OmegaConf.create({"rollout": {"threads": None}})) is None
    assert rollout_threads(OmegaConf.create({"rollout": {"threads": 1}})) == 1


@pytest.mark.parametrize("batch_scenes", [True, False])
def test_a_compiled_step_is_warmed_on_every_rollout_it_will_time(monkeypatch, batch_scenes):
    """The compiles of the shapes a compiled step meets happen before the timing, not in it;
    an eager step warms up on one short rollout only."""
    from simdata import learned, trajectory

    from physgnn.evaluation import rollouts
    from physgnn.models.capture import compile_in_place, is_compiled
    from physgnn.models.constrained import ConstrainedSimulator

    calls = []
    monkeypatch.setattr(rollouts, "rollout", lambda sim, trajs: calls.append(trajs))
    splits = {"test": [trajectory(2, frames=9, seed=0), trajectory(3, frames=9, seed=1)]}
    splits["ood"] = [trajectory(4, frames=9, seed=2)]
    sim = learned(H=1, M=1, hidden=8, neighbor_backend="torch").eval()
    rollouts.warm_up(RunInfo("eager", "baseline", simulator=sim), splits, batch_scenes)
    assert [[t.n_frames for t in group] for group in calls] == [[int(sim.H) + 3]]
    compile_in_place(sim, "default", True, 4, method="head")  # lazy: nothing compiles here
    assert is_compiled(sim) and is_compiled(ConstrainedSimulator(sim, 1))
    calls.clear()
    rollouts.warm_up(RunInfo("compiled", "baseline", simulator=sim), splits, batch_scenes)
    expected = [splits["test"], splits["ood"]]
    if not batch_scenes:
        expected = [[t] for group in expected for t in group]
    assert calls == expected
