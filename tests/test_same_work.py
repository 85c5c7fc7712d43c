"""Accuracy versus time on the same work: pybullet's rows of metrics.csv
(physgnn.evaluation.same_work) and the view of them (physgnn.report.same_work)."""

from __future__ import annotations

import itertools
import math
import multiprocessing as mp
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from physgnn.data.dataset import read_split
from physgnn.errors import ConfigError, forked_worker
from physgnn.evaluation import same_work as engine_work
from physgnn.evaluation import turns
from physgnn.evaluation.runs import RunInfo
from physgnn.models.baselines import GravityOnlySimulator
from physgnn.physics.trajectory import FRAME_KEYS
from physgnn.report import same_work
from physgnn.report.format import fmt_stat
from physgnn.report.sections import group_table
from physgnn.report.table import COLUMNS, frame_rate, group_rows, run_frame_rates


def row(run, experiment, mse20, fps, split="test", substeps=None, trajectory="t0"):
    r = dict.fromkeys(COLUMNS)
    r.update(
        run=run,
        experiment=experiment,
        overrides="",
        split=split,
        trajectory=trajectory,
        mse20=mse20,
        chamfer=mse20,
        fps=fps,
        substeps=substeps,
    )
    return r


def engine(k, mse20, fps):
    return row(f"pybullet-{k}", "pybullet", mse20, fps, substeps=k)


# pybullet: 1 ms at 1.0, 5 ms at 0.1, 20 ms at 0.01 (ms per frame = 1000 / fps)
ENGINE_ROWS = [engine(1, 1.0, 1000.0), engine(5, 0.1, 200.0), engine(20, 0.01, 50.0)]


def test_pareto_frontier_hand_computed():
    costs = [1.0, 2.0, 2.0, 3.0, 0.5, 4.0, 1.0, math.nan]
    errors = [5.0, 3.0, 4.0, 3.0, 9.0, 1.0, 5.0, 0.0]
    # 4 (0.5, 9) < 0 (1, 5) < 1 (2, 3) < 5 (4, 1); 6 duplicates 0; 2 and 3 dominated by 1
    assert same_work.pareto_frontier(costs, errors) == [4, 0, 1, 5]
    assert same_work.pareto_frontier([], []) == []
    with pytest.raises(ValueError):
        same_work.pareto_frontier([1.0], [])


def test_a_fake_learned_run_lands_where_its_cost_and_error_put_it():
    # 2 ms at 0.5: nothing cheaper is as accurate -> on the front, between pybullet-1 and -5;
    # 10 ms at 0.2: pybullet-5 is cheaper (5 ms) and more accurate (0.1) -> off the front
    fast = row("runs/fast", "baseline", 0.5, 500.0)
    slow = row("runs/slow", "slower", 0.2, 100.0)
    pts = same_work.points([fast, slow, *ENGINE_ROWS], "test", "mse20")
    assert [(p.label, p.ms_per_frame, p.error, p.kind) for p in pts] == [
        ("baseline: default", 2.0, 0.5, "learned"),
        ("slower: default", 10.0, 0.2, "learned"),
        ("pybullet-1", 1.0, 1.0, "pybullet"),
        ("pybullet-5", 5.0, 0.1, "pybullet"),
        ("pybullet-20", 20.0, 0.01, "pybullet"),
    ]
    on_front = [p.label for p in same_work.front(pts)]
    assert on_front == ["pybullet-1", "baseline: default", "pybullet-5", "pybullet-20"]
    table = same_work.split_table([fast, slow, *ENGINE_ROWS], "test")
    marks = {ln.split(" | ")[0][2:]: ln.split(" | ")[-2] for ln in table.splitlines()[2:]}
    assert marks == {
        "baseline: default": "✓",
        "slower: default": "",
        "pybullet-1": "✓",
        "pybullet-5": "✓",
        "pybullet-20": "✓",
    }


def test_a_groups_rate_is_its_frames_over_its_seconds():
    """One scene at a time each row has its own rate: 100 frames at 10 frames/s (10 s) and 50
    at 50 (1 s) are 150 frames in 11 s, not the mean of the rates (30); rows of one batch share
    one rate and give it."""
    alone = [
        row("runs/a", "baseline", 0.5, 10.0) | {"n_frames": 100},
        row("runs/a", "baseline", 0.5, 50.0, trajectory="t1") | {"n_frames": 50},
    ]
    assert frame_rate(alone) == pytest.approx(150 / 11)
    [point] = same_work.points(alone, "test", "mse20")
    assert point.ms_per_frame == pytest.approx(1000 * 11 / 150)
    batch = [r | {"fps": 40.0} for r in alone]
    assert frame_rate(batch) == pytest.approx(40.0)
    assert frame_rate([row("runs/a", "baseline", 0.5, None)]) is None


def test_a_configurations_rate_is_each_seeds_frames_over_its_seconds_then_their_mean():
    """The overview's frames/s (test) and its figure: seed a runs 150 frames in 11 s, seed b
    one batch at 40 frames/s; mean and population std over the two seeds, not over rows."""
    seed_a = [
        row("runs/a", "baseline", 0.5, 10.0) | {"n_frames": 100},
        row("runs/a", "baseline", 0.5, 50.0, trajectory="t1") | {"n_frames": 50},
    ]
    seed_b = [r | {"run": "runs/b", "fps": 40.0} for r in seed_a]
    a, b = 150 / 11, 40.0
    mean, std, count = run_frame_rates(seed_a + seed_b)
    assert (mean, std, count) == (pytest.approx((a + b) / 2), pytest.approx(abs(a - b) / 2), 2)
    overview = group_table(group_rows(seed_a + seed_b), splits=("test",))
    assert overview.splitlines()[0].endswith("| frames/s (test) | diverged |")
    assert f"| {fmt_stat((mean, std, 2))} | no |" in overview
    assert run_frame_rates([row("runs/a", "baseline", 0.5, None)]) is None


def test_a_diverged_learned_run_is_never_on_the_front():
    best = row("runs/best", "baseline", 1e-6, 1e6) | {"diverged_at": 7}
    assert "baseline: default" not in {
        p.label for p in same_work.front(same_work.points([best, *ENGINE_ROWS], "test", "mse20"))
    }


def test_the_view_reads_only_its_split_and_says_when_pybullet_is_missing():
    ood = [row("runs/a", "baseline", 0.5, 500.0, split="ood")]
    assert same_work.points(ood + ENGINE_ROWS, "ood", "mse20")[0].label == "baseline: default"
    assert len(same_work.points(ood + ENGINE_ROWS, "ood", "mse20")) == 1
    assert "No pybullet rows" in same_work.section(ood)


def learned_run(dataset, H):
    return RunInfo(
        name="runs/x",
        experiment="baseline",
        run_dir=dataset,
        dataset=dataset,
        simulator=SimpleNamespace(H=H),
    )


@pytest.fixture(scope="module")
def tiny(tiny_dataset):
    return {tiny_dataset: {s: read_split(tiny_dataset / f"{s}.h5") for s in ("test", "ood")}}


def test_pybullet_at_the_truths_settings_from_frame_0_is_the_truth(tiny, tiny_dataset):
    jobs = engine_work.engine_jobs([learned_run(tiny_dataset, 0)], several=False)
    rows = engine_work.engine_rows(jobs, tiny, [40], processes=1, tol=0.0)
    assert [r["run"] for r in rows] == ["pybullet-40"] * 5 and {r["substeps"] for r in rows} == {40}
    assert [r["trajectory"] for r in rows] == [
        "traj_00000",
        "ood_cubes",
        "ood_cubes_ramps",
        "ood_resting_hit",
        "ood_spaced_drop",
    ]
    for r in rows:
        assert r["mse"] == r["chamfer"] == 0.0 and r["fps"] > 0  # (20 frames: no mse20)


def test_pybullet_starts_where_the_learned_run_starts(tiny, tiny_dataset):
    """From frame H: the first H+1 frames are the truth's, the rest the engine's, and the rows
    of a split run in two processes score as one at a time (each row the split's rate)."""
    truth = tiny[tiny_dataset]["ood"][1]
    [pred] = engine_work.engine_split([truth], 2, 1, processes=None)
    assert (pred.start, pred.n_frames, pred.diverged_at) == (2, truth.n_frames, None)
    for key in ("pos", "quat"):
        np.testing.assert_array_equal(getattr(pred, key)[:3], getattr(truth, key)[:3])
    assert not np.array_equal(pred.pos[3:], truth.pos[3:])  # 1 substep, not 40
    np.testing.assert_allclose(pred.vel[3], (pred.pos[3] - pred.pos[2]) / truth.dt, rtol=1e-5)
    jobs = engine_work.engine_jobs([learned_run(tiny_dataset, 2)], several=False)
    alone = engine_work.engine_rows(jobs, tiny, [1], processes=None, tol=0.0)
    pooled = engine_work.engine_rows(jobs, tiny, [1], processes=2, tol=0.0)
    for a, b in zip(alone, pooled, strict=True):
        assert {k: a[k] for k in ("mse", "chamfer", "energy_gain")} == {
            k: b[k] for k in ("mse", "chamfer", "energy_gain")
        }
    assert len({r["fps"] for r in pooled if r["split"] == "ood"}) == 1
    assert {r["threads"] for r in alone} == {1} and {r["threads"] for r in pooled} == {2}


@pytest.mark.parametrize("processes", [None, 1])
def test_one_process_gives_the_split_its_rate_and_one_at_a_time_each_its_own(
    tiny, tiny_dataset, monkeypatch, processes
):
    """A clock that reads 0, 0, 1, 1, 4, 4: the first scene takes 1 s, the second 3 s. One at a
    time (None), each row its own frames/s; the split in one process, every row the split's
    scene-frames per wall-clock second (as a batched learned rollout on one thread)."""
    trajs = tiny[tiny_dataset]["ood"][:2]
    clock = iter([0.0, 0.0, 1.0, 1.0, 4.0, 4.0])
    monkeypatch.setattr(engine_work.time, "perf_counter", lambda: next(clock))
    preds = engine_work.engine_split(trajs, 0, 1, processes=processes)
    frames = [t.n_frames - 1 for t in trajs]
    expected = [frames[0] / 1.0, frames[1] / 3.0] if processes is None else [sum(frames) / 4.0] * 2
    assert [p.fps for p in preds] == pytest.approx(expected, rel=1e-12)


def test_engine_settings_come_from_the_truth_with_the_substeps_replaced(tiny, tiny_dataset):
    truth = tiny[tiny_dataset]["test"][0]
    settings = engine_work.engine_of(truth, 3)
    assert settings["substeps"] == 3 and settings["contact_erp"] == 0.005
    assert engine_work.engine_of(truth.__class__(**{**truth.__dict__, "attrs": {}}), 3) == {
        "substeps": 3
    }
    assert set(FRAME_KEYS) <= set(truth.__dict__)


@pytest.mark.parametrize(
    "settings, text",
    [
        ({"substeps": [], "processes": None}, "pybullet.substeps must be a list"),
        ({"substeps": [0], "processes": None}, "pybullet.substeps must be a list"),
        ({"substeps": [2], "processes": 0}, "pybullet.processes must be a whole number"),
    ],
)
def test_bad_pybullet_settings_are_one_line(settings, text):
    with pytest.raises(ConfigError, match=text):
        engine_work.check_settings(OmegaConf.create(settings))
    assert engine_work.check_settings(None) is None
    assert engine_work.check_settings(OmegaConf.create({"substeps": [1, 5], "processes": 3})) == (
        [1, 5],
        3,
    )


def _a_parallel_loop(_) -> tuple[int, float]:
    """A worker's torch threads and a copy large enough for ATen to split across threads."""
    return torch.get_num_threads(), float(torch.cat([torch.ones(200_000)] * 2).sum())


def test_forked_workers_run_torch_after_the_parent_ran_it_on_two_threads():
    """GNU OpenMP is not fork-safe: before ``forked_worker``, ``make eval``'s pybullet pool hung
    for good at its first parallel loop once the parent's torch had run one on 2 threads."""
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        (torch.randn(4_000_000) * 2).sum()  # the parent's OpenMP team of 2 threads exists now
        with mp.get_context("fork").Pool(2, initializer=forked_worker) as pool:
            answers = pool.map_async(_a_parallel_loop, range(2))
            try:
                got = answers.get(timeout=60)
            except mp.TimeoutError:
                pool.terminate()
                pytest.fail("a forked worker hung in its first parallel loop")
    finally:
        torch.set_num_threads(threads)
    assert got == [(1, 400_000.0)] * 2


def test_turns_time_each_learned_rollout_and_pybullet_again_and_keep_the_scores(tiny, tiny_dataset):
    job = RunInfo(
        name="runs/g",
        experiment="baseline",
        run_dir=tiny_dataset,
        dataset=tiny_dataset,
        simulator=GravityOnlySimulator(),
    )
    engines = engine_work.engine_jobs([job], several=False)
    fps = turns.timed_in_turns([(job, 1)], engines, tiny, ([1, 2], 1, 2))
    names = ("runs/g", "pybullet-1", "pybullet-2")
    assert set(fps) == {(n, s) for n in names for s in ("test", "ood")}
    assert all(rate > 0 for rate in fps.values())
    rows = [row("runs/g", "baseline", 0.5, 1.0, split=s) for s in ("test", "ood")]
    rows.append(row("static", "static", 1.0, 3.0))
    out = turns.retimed(rows, fps)
    assert [r["fps"] for r in out] == [fps["runs/g", "test"], fps["runs/g", "ood"], 3.0]
    assert [r["mse20"] for r in out] == [0.5, 0.5, 1.0]


def test_a_rows_rate_in_turns_is_the_median_of_its_rounds(tiny, tiny_dataset, monkeypatch):
    rates = itertools.cycle([1.0, 50.0, 5.0, 3.0, 60.0, 2.0])  # learned, pybullet; 3 rounds
    monkeypatch.setattr(turns, "predict_split", lambda *a: [SimpleNamespace(fps=next(rates))])
    monkeypatch.setattr(turns, "engine_split", lambda *a: [SimpleNamespace(fps=next(rates))])
    job = learned_run(tiny_dataset, 0)
    engines = engine_work.engine_jobs([job], several=False)
    fps = turns.timed_in_turns([(job, 1)], engines, tiny, ([1], 1, 3))
    assert fps["runs/x", "test"] == fps["runs/x", "ood"] == 5.0  # of 1, 5, 60
    assert fps["pybullet-1", "test"] == fps["pybullet-1", "ood"] == 3.0  # of 50, 3, 2


def test_turns_are_a_whole_number_from_zero():
    assert turns.check_turns(None) == 0 and turns.check_turns({"turns": 2}) == 2
    with pytest.raises(ConfigError, match=r"^pybullet.turns must be a whole number >= 0"):
        turns.check_turns({"turns": -1})
