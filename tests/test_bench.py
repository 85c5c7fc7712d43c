"""make bench (quick mode), its FLOP counts, targets table and the Pareto view."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from gpukit import OPS_PER_TRAINING_STEP
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from torch.utils.flop_counter import FlopCounterMode

from physgnn import CONF_DIR
from physgnn.benchmark import crossover, crossover_table, interleaved
from physgnn.benchmark import gpu as gpu_module
from physgnn.benchmark import scenes as bench_scenes
from physgnn.benchmark.crossover_summary import (
    front_from,
    judged,
    learned_on_front,
    spread,
    summary,
)
from physgnn.benchmark.gpu import gpu_section
from physgnn.benchmark.learned import frame_states, time_cases
from physgnn.benchmark.profile import step_flops
from physgnn.benchmark.run import bench, merged_config, quick_config
from physgnn.benchmark.source import BenchError, Source, learned_source, make_simulator
from physgnn.benchmark.targets import targets
from physgnn.benchmark.training_tables import gpu_section as gpu_tables
from physgnn.data.stats import compute_stats
from physgnn.groundtruth.engine import simulate
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.models.profiling import StepTimer
from physgnn.nn.epd import EncodeProcessDecode, Widths
from physgnn.report import pareto

CONF = CONF_DIR


QUICK = ("quick=true", "threads=1")
READINESS_PARTS = ("train_step", "rollout_frame")


def _cfg(*overrides):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose("bench", overrides=list(overrides))


# ---------------------------------------------------------------------- the whole bench, tiny
@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick bench without its compiled rows, whose compiles take about 90 % of its time
    (:func:`test_the_compiled_rows_dispatch_fewer_ops_within_the_budget`, slow, has them)."""
    out = tmp_path_factory.mktemp("bench")
    result = bench(_cfg(*QUICK, f"out_dir={out}", "gpu_readiness.compiled=false"))
    return out, result


def test_bench_json_has_exactly_the_agreed_keys(quick):
    out, result = quick
    data = json.loads((out / "bench.json").read_text())
    assert data == json.loads(json.dumps(result))
    assert set(data) == {
        "wall_s",
        "run",
        "machine",
        "learned",
        "pybullet",
        "interleaved",
        "crossover",
        "training",
        "gpu_readiness",
        "gpu",
    }
    kinds = ("", "_fixed_capacity")  # gpu_readiness.compiled=false: no compiled rows
    readiness = data["gpu_readiness"]
    assert set(readiness) == {f"{p}{kind}" for p in READINESS_PARTS for kind in kinds}
    for counts in readiness.values():
        assert set(counts) == {"syncs", "kernels", "copies", "host_ms"}
        assert counts["syncs"] is not None and counts["kernels"] > 0
    if not torch.cuda.is_available():
        assert data["gpu"] is None
        assert "Skipped: torch saw no CUDA device" in (out / "bench.md").read_text()
    assert set(data["machine"]) == {"cpu", "threads", "matmul_gflops"}
    assert set(data["training"]) == {"pairs_per_s", "nodes_per_s", "share_of_matmul"}
    assert data["run"] == "random weights" and data["wall_s"] > 0  # quick: run null
    assert f"({data['wall_s']:.0f} s in all)" in (out / "bench.md").read_text()
    learned_keys = {
        "config",
        "weights",
        "n_spheres",
        "fps",
        "graph_ms",
        "network_ms",
        "integrate_ms",
        "gflop_per_step",
        "share_of_matmul",
    }
    assert data["learned"] and all(set(r) == learned_keys for r in data["learned"])
    pyb_keys = {"n_spheres", "substeps", "fps", "mse_vs_reference"}
    assert data["pybullet"] and all(set(r) == pyb_keys for r in data["pybullet"])


@pytest.mark.slow
def test_the_compiled_rows_dispatch_fewer_ops_within_the_budget(tmp_path):
    """The quick bench with its compiled rows (the default): only the ops outside the
    compiled regions are counted there, fewer than eager, and the default recipe's compiled
    training step keeps to the op budget while the eager one does not."""
    result = bench(_cfg(*QUICK, f"out_dir={tmp_path}"))
    readiness = result["gpu_readiness"]
    kinds = ("", "_fixed_capacity", "_compiled")
    assert set(readiness) == {f"{p}{kind}" for p in READINESS_PARTS for kind in kinds}
    for part, counts in readiness.items():
        assert (counts["syncs"] is None) == part.endswith("_compiled")
    for part in READINESS_PARTS:
        assert 0 < readiness[f"{part}_compiled"]["kernels"] < readiness[part]["kernels"]
    steps = readiness["train_step_compiled"]["kernels"], readiness["train_step"]["kernels"]
    assert steps[0] <= OPS_PER_TRAINING_STEP < steps[1]
    assert "train step compiled" in (tmp_path / "bench.md").read_text()


def test_bench_values_are_sane(quick):
    out, result = quick
    assert result["machine"]["threads"] == 1 and result["machine"]["matmul_gflops"] > 0
    # quick: baseline on both sizes, M1 and the constraint stage on 10 spheres only
    assert [(r["config"], r["n_spheres"]) for r in result["learned"]] == [
        ("baseline", 10),
        ("baseline", 30),
        ("M1", 10),
        ("constraints", 10),
    ]
    for r in result["learned"]:
        parts = r["graph_ms"] + r["network_ms"] + r["integrate_ms"]
        assert r["fps"] > 0 and min(r["graph_ms"], r["network_ms"], r["integrate_ms"]) > 0
        assert parts <= 1000 / r["fps"] * 1.5  # medians of parts ~ median of totals
        assert r["gflop_per_step"] > 0 and 0 < r["share_of_matmul"] <= 1
    # sizes at 10 substeps, and the accuracy sweep (10 spheres: 1 and 2 substeps)
    keys = [(r["n_spheres"], r["substeps"]) for r in result["pybullet"]]
    assert keys == [(10, 1), (10, 2), (10, 10), (30, 10)]
    for r in result["pybullet"]:
        assert r["fps"] > 0
        swept = r["substeps"] in (1, 2)
        assert (r["mse_vs_reference"] is not None) == swept
        if swept:
            assert r["mse_vs_reference"] >= 0
    assert result["training"]["pairs_per_s"] > 0
    assert result["training"]["nodes_per_s"] > result["training"]["pairs_per_s"]
    md = (out / "bench.md").read_text()
    for title in (
        "## Machine",
        "## Targets",
        "## Learned simulator",
        "## pybullet frame rate",
        "substeps versus accuracy",
        "## Training throughput",
        "Cost follows activity",
    ):
        assert title in md


def test_engine_table_prints_the_free_fall_lag_per_substep_count(quick):
    # semi-implicit Euler lags ½gt² by g·h·t/2 after t = 4 s (h = 0.1 s / substeps)
    out, _ = quick
    rows = json.loads((out / "bench_extra.json").read_text())["pybullet_accuracy"]
    assert sorted(r["substeps"] for r in rows) == [1, 2, 8]
    for r in rows:
        assert r["free_fall_error"] == pytest.approx(9.81 * 0.1 / r["substeps"] * 2, rel=1e-3)
    md = (out / "bench.md").read_text()
    assert "free-fall error after 4 s (m)" in md
    assert "| 8 (reference) |" in md


def test_bench_activity_rows(quick):
    out, _ = quick
    rows = {
        r["case"].split(" (")[0]: r
        for r in json.loads((out / "bench_extra.json").read_text())["activity"]
    }
    assert rows["contacts off"]["pp_edges"] == 0 < rows["contacts on"]["pp_edges"]
    assert rows["no walls"]["ps_edges"] <= rows["no walls"]["nodes"]  # ground edges only
    assert (
        rows["no walls"]["ps_edges"] < rows["walls"]["ps_edges"]
        or rows["walls"]["ps_edges"] == rows["walls"]["nodes"]
    )
    extra = json.loads((out / "bench_extra.json").read_text())
    [roll] = extra["rollout"]
    assert roll["n_spheres"] == 30 and roll["fps"] > 0 and roll["frames"] >= 1
    one, two = extra["batched"]
    assert (one["scenes"], two["scenes"]) == (1, 2)
    assert math.isclose(two["gflop_per_step"], 2 * one["gflop_per_step"])  # same scene twice
    assert math.isclose(two["ms_per_scene"], two["batch_ms"] / 2)
    sleeping = [r for k, r in rows.items() if "sleeping on" in k][0]
    awake = [r for k, r in rows.items() if "sleeping off" in k][0]
    assert sleeping["nodes"] < awake["nodes"] == 22


def test_bench_rejects_bad_threads(tmp_path):
    with pytest.raises(BenchError, match="threads"):
        bench(_cfg("quick=true", "threads=0", f"out_dir={tmp_path}"))


# ---------------------------------------------------------------------------------- FLOPs
def _paired_graph(n: int, pairs: int, f: int) -> tuple[torch.Tensor, torch.Tensor]:
    """pp edges ``[2, 2·pairs]`` in the paired layout and ps edges ``[2, f]`` from plane 0."""
    src = torch.arange(pairs) % n
    dst = (src + 1 + torch.arange(pairs) % (n - 1)) % n
    pp = torch.cat([torch.stack([src, dst]), torch.stack([dst, src])], 1)
    return pp, torch.stack([torch.zeros(f, dtype=torch.long), torch.arange(f) % n])


@pytest.mark.parametrize(
    "third_law,surfaces,concat",
    [(True, True, "auto"), (False, False, "never"), (True, True, "always")],
)
def test_flops_per_step_equals_counted_matmuls(third_law, surfaces, concat):
    torch.manual_seed(0)
    net = EncodeProcessDecode(
        Widths(20), hidden=16, M=2, third_law=third_law, use_surfaces=surfaces, concat_trick=concat
    )
    n, pairs, f = 7, 5, 6
    pp, ps = _paired_graph(n, pairs, f)
    with FlopCounterMode(display=False) as counter:
        net(torch.randn(n, 20), pp, torch.randn(2 * pairs, 4), ps, torch.randn(f, 10))
    assert counter.get_total_flops() == net.flops_per_step(n, 2 * pairs, f)


def test_training_flops_count_forward_and_backward():
    """step_flops counts a loss graph 3 times (forward, and backward's two products per
    layer): counted by torch, backward skips the encoders' first-layer input gradients, so
    the count is an upper bound, within 1 % at the baseline's width."""
    torch.manual_seed(0)
    net = EncodeProcessDecode(Widths(20), hidden=128, M=5)
    n, pairs, f = 40, 30, 45
    pp, ps = _paired_graph(n, pairs, f)
    with FlopCounterMode(display=False) as counter:
        net(
            torch.randn(n, 20), pp, torch.randn(2 * pairs, 4), ps, torch.randn(f, 10)
        ).sum().backward()
    sim = SimpleNamespace(network=net)
    counted, size = counter.get_total_flops(), (n, 2 * pairs, f)
    assert 0.99 * step_flops(sim, [], [size]) <= counted <= step_flops(sim, [], [size])
    assert step_flops(sim, [size, size], [size]) == 5 * net.flops_per_step(*size)


def test_step_timer_records_the_size_of_every_graph_it_watched():
    cfg = _cfg("quick=true")
    scene = bench_scenes.bench_scene(cfg.scene, 12, np.random.default_rng(0), 8.0, 4.0, 5)
    traj = simulate(scene, {"substeps": 2})
    one_pass = {
        "network": {"hidden": 16, "M": 2},
        "contacts": {"contact_passes": 0},
    }  # one build per step
    sim = make_simulator(cfg.model, one_pass, compute_stats([traj]))
    states = frame_states(traj, sim.H)[:2]
    timer = StepTimer()
    with timer.watch(sim):
        for state in states:
            sim(state)
    graphs = [sim.graph_builder(s) for s in states]
    assert timer.sizes == [(12, g.pp_index.shape[1], g.ps_index.shape[1]) for g in graphs]


def test_time_cases_counts_the_flops_of_the_graphs_it_ran(tmp_path):
    cfg = _cfg("quick=true")
    rng = np.random.default_rng(0)
    scene = bench_scenes.bench_scene(cfg.scene, 12, rng, 8.0, 4.0, 5)
    assert scene.n_spheres == 12
    traj = simulate(scene, {"substeps": 2})
    sim = make_simulator(cfg.model, {"network": {"hidden": 16, "M": 2}}, compute_stats([traj]))
    states = frame_states(traj, sim.H)
    t = time_cases([(sim, states)], 2)[0]
    expected = 0
    for s in states[:2]:
        g = sim.graph_builder(s)
        expected += sim.network.flops_per_step(12, g.pp_index.shape[1], g.ps_index.shape[1])
    assert t["network_flop"] == expected
    assert math.isclose(t["gflop_per_step"], expected / 2 / 1e9)


# -------------------------------------------------------------------------------- targets
def _learned(n, fps, graph, network, share):
    total = 1000 / fps
    return {
        "config": "baseline",
        "n_spheres": n,
        "fps": fps,
        "total_ms": total,
        "graph_ms": graph * total,
        "network_ms": network,
        "share_of_matmul": share,
    }


def _size(n, substeps, ratio, load, window="landed"):
    return {
        "window": window,
        "n_spheres": n,
        "matched_substeps": substeps,
        "matched_ratio": ratio,
        "loadavg_start": load,
    }


def test_targets_table_met_and_not_met():
    extra = {
        "learned": [
            _learned(154, 450.0, 0.2, 1.0, 0.4),
            _learned(300, 200.0, 0.2, 1.0, 0.55),
            _learned(1000, 50.0, 0.3, 1.0, 0.5),
            _learned(10000, 4.0, 0.1, 1.0, 0.5),
        ],
        "training": {"share_of_matmul": 0.65, "gflops": 100.0, "nodes_per_s": 30_000.0},
    }
    cases = [_size(154, 5, 3.0, 0.5), _size(1000, 5, 4.0, 2.5), _size(10000, 2, 0.5, 2.5)]
    # the in-motion window is not judged by the speed target
    result = {"crossover": {"cases": [*cases, _size(154, None, None, 0.5, "in_motion")]}}
    fps154, fps1000, share, graph, linear, pybullet, train_share, nodes = targets(result, extra)
    assert fps154[1:] == ["450.0 FPS", "met"]
    assert fps1000[1:] == ["50.0 FPS (needs ×2.4)", "not met"]
    assert share[2] == "met"  # 40 % at 154 spheres is not judged: from 300 up
    assert graph[2] == "not met"  # 30 % at 1000 spheres
    assert linear[1:] == ["1.25", "met"]  # (250 ms / 10 000) / (20 ms / 1000)
    assert pybullet[0].startswith("learned FPS over the fastest pybullet setting at least as")
    assert pybullet[1] == (
        "154: 3.00× against 5 substeps (load 0.5); 1000: 4.00× against 5 substeps (load 2.5)"
    )
    assert pybullet[2] == "not met"  # 4 < 5 at 1 000 spheres
    result["crossover"]["cases"][1] = _size(1000, 10, 5.5, 0.5)
    assert targets(result, extra)[5][2] == "met"
    result["crossover"]["cases"][1] = _size(1000, None, None, 0.5)  # none as accurate
    assert targets(result, extra)[5][1:] == [
        "154: 3.00× against 5 substeps (load 0.5); 1000: no setting tried is as accurate",
        "not met",
    ]
    assert targets({"crossover": None}, extra)[5][1:] == ["–", "not met"]
    assert train_share[1:] == ["65% (100.0 GFLOP/s)", "met"]
    assert nodes[1:] == ["30.0 k nodes/s", "not met (needs ×1.3)"]
    # the graph share is judged from 154 spheres up: 50 % at 10 spheres does not count
    extra["learned"][2] = _learned(1000, 50.0, 0.2, 1.0, 0.45)
    extra["learned"].append(_learned(10, 500.0, 0.5, 1.0, 0.1))
    rows = targets(result, extra)
    assert rows[3][2] == "met"
    assert rows[2][2] == "not met (needs ×1.1)"  # 45 % at 1000 spheres
    extra["training"]["share_of_matmul"] = 0.59
    assert targets(result, extra)[6][2] == "not met (needs ×1.02)"  # close calls show 2 decimals
    del extra["training"]
    assert len(targets(result, extra)) == 6  # no training rows without a training run


# ------------------------------------------------------------------------ interleaved rounds
def test_taking_turns_keeps_each_rounds_ratio_and_their_median(monkeypatch):
    # a busy spell in round 2 slows both halves: its ratio stays near the others
    learned = iter([100.0, 40.0, 120.0, 90.0])
    engine = iter([50.0, 25.0, 40.0, 60.0])
    monkeypatch.setattr(interleaved, "step_once", lambda sim, state: None)
    monkeypatch.setattr(interleaved, "learned_fps", lambda sim, states: next(learned))
    monkeypatch.setattr(
        interleaved, "timed_pybullet", lambda start, engine_cfg: (None, next(engine))
    )
    turns = interleaved.taking_turns(None, [None], None, {}, rounds=4)
    assert turns["learned_fps"] == [100.0, 40.0, 120.0, 90.0]
    assert turns["pybullet_fps"] == [50.0, 25.0, 40.0, 60.0]
    assert turns["ratios"] == [2.0, 1.6, 3.0, 1.5]
    assert turns["median_ratio"] == 1.8  # (1.6 + 2.0) / 2
    assert turns["loadavg_start"] >= 0 and turns["loadavg_end"] >= 0


def test_quick_bench_takes_turns_and_names_the_model_in_the_targets_heading(quick):
    out, result = quick
    [row] = result["interleaved"]
    assert (row["config"], row["n_spheres"], row["substeps"], len(row["ratios"])) == (
        "baseline",
        10,
        10,
        2,
    )
    ratios = [a / b for a, b in zip(row["learned_fps"], row["pybullet_fps"], strict=True)]
    assert row["ratios"] == ratios and row["median_ratio"] == sum(ratios) / 2
    md = (out / "bench.md").read_text()
    model = _cfg().model
    heading = (
        f"## Targets (baseline M={model.network.M} H={model.H} "
        f"{model.graph.connectivity} h={model.network.hidden})"
    )
    assert heading in md and "## Learned against pybullet, taking turns" in md
    assert "![pybullet accuracy versus time on the bench pile](pybullet_accuracy.png)" in md
    assert (out / "pybullet_accuracy.png").stat().st_size > 1000


def test_interleaved_configs_must_be_learned_configs(tmp_path):
    cfg = _cfg("threads=1", f"out_dir={tmp_path}", "interleaved.configs=[nope]")
    with pytest.raises(BenchError, match="interleaved.configs names nope, not among"):
        bench(cfg)


# -------------------------------------------------------------------------------- crossover
def _point(name, mse20, fps, ratio=None, diverged=0):
    learned = name.startswith("learned")
    return {
        "simulator": name,
        "setting": name.split()[1] if learned else None,
        "substeps": None if learned else int(name.split("-")[1]),
        "mse20": mse20,
        "fps": fps,
        "ratio": ratio,
        "diverged": diverged,
    }


def test_crossover_judges_the_front_and_the_matched_setting():
    engine = [
        _point("pybullet-1", 1.0, 400.0, 0.25),
        _point("pybullet-5", 0.1, 100.0, 1.0),
        _point("pybullet-20", 0.01, 25.0, 4.0),
    ]
    # 100 FPS at 0.5: pybullet-5 is as fast and more accurate -> off; matched: pybullet-5
    assert judged([_point("learned a", 0.5, 100.0), *engine]) == {
        "front": ["pybullet-1", "pybullet-5", "pybullet-20"],
        "on_front": False,
        "matched_substeps": 5,
        "matched_ratio": 1.0,
    }
    # 200 FPS at 0.05, and a second setting at 50 FPS and 0.02: both on the front, which
    # pybullet-5 leaves; the fastest as accurate as the first: 20 substeps
    two = [_point("learned a", 0.05, 200.0), _point("learned b", 0.02, 50.0)]
    assert judged([*two, *engine]) == {
        "front": ["pybullet-1", "learned a", "learned b", "pybullet-20"],
        "on_front": True,
        "matched_substeps": 20,
        "matched_ratio": 4.0,
    }
    # more accurate than every setting tried: on the front, no matched setting
    assert judged([_point("learned a", 0.001, 1.0), *engine])["matched_substeps"] is None
    # a setting that diverged in a draw is never on the front, nor matched
    off = judged([_point("learned a", 0.05, 200.0, diverged=1), *engine])
    assert off == {
        "front": ["pybullet-1", "pybullet-5", "pybullet-20"],
        "on_front": False,
        "matched_substeps": None,
        "matched_ratio": None,
    }

    def cases(*fronts: bool) -> list[dict]:
        return [
            {"n_spheres": n, "on_front": f} for n, f in zip((154, 1000, 3000), fronts, strict=True)
        ]

    assert front_from(cases(False, True, True)) == 1000
    assert front_from(cases(True, False, True)) == 3000
    assert front_from(cases(True, True, False)) is None


def test_the_learned_settings_on_the_front_are_listed_by_size():
    a, b, p1 = (
        _point("learned a", 0.1, 10.0),
        _point("learned b", 0.2, 20.0),
        _point("pybullet-1", 1, 5),
    )
    cases = [
        {"n_spheres": 1000, "points": [a, b, p1], "front": ["learned b"]},
        {"n_spheres": 154, "points": [a, b, p1], "front": ["learned a", "learned b"]},
    ]
    assert learned_on_front(cases) == {"a": [154], "b": [154, 1000]}


def _row(name, mse20, fps, ratio=None, diverged_at=None):
    point = _point(name, mse20, fps, ratio)
    del point["diverged"]
    return point | {"diverged_at": diverged_at, "chamfer": fps / 100, "depth_sphere": 0.0}


def test_the_draws_are_summarised_by_median_and_spread():
    assert spread([None, 3.0, 1.0]) == (2.0, 1.0, 3.0)
    assert spread([None, None]) == (None, None, None)
    draws = [
        [_row("learned a", 0.2, 10.0), _row("pybullet-1", 0.1, 100.0, 0.1)],
        [_row("learned a", 0.6, 30.0, diverged_at=7), _row("pybullet-1", 0.3, 300.0, 0.1)],
        [_row("learned a", 0.4, 20.0), _row("pybullet-1", None, 200.0, 0.2)],
    ]
    for row in (r for rows in draws for r in rows):
        row["depth_ground"] = None
    learned, engine = summary(draws)
    assert learned == {
        "simulator": "learned a",
        "setting": "a",
        "substeps": None,
        **{"mse20": 0.4, "mse20_min": 0.2, "mse20_max": 0.6},
        **{"fps": 20.0, "fps_min": 10.0, "fps_max": 30.0},
        **{"ratio": None, "ratio_min": None, "ratio_max": None},
        **{"chamfer": 0.2, "depth_sphere": 0.0, "depth_ground": None},
        "diverged": 1,
    }
    # a draw without a score (None) is left out of its median and spread
    assert (engine["mse20"], engine["mse20_min"], engine["mse20_max"]) == (0.2, 0.1, 0.3)
    assert (engine["fps"], engine["ratio"], engine["ratio_max"]) == (200.0, 0.1, 0.2)
    assert engine["diverged"] == 0


def _tiny_source(trained: bool) -> Source:
    cfg = _cfg("quick=true")
    traj = simulate(bench_scenes.bench_scene(cfg.scene, 6, np.random.default_rng(0), 8, 4, 6), {})
    stats = compute_stats([traj])
    model = OmegaConf.merge(cfg.model, {"network": {"hidden": 8, "M": 1}})
    sim = make_simulator(model, {}, stats) if trained else None
    return Source(model, sim, "a run" if trained else "random weights", stats)


def test_a_source_gives_trained_copies_and_random_weights_apart():
    source = _tiny_source(trained=True)
    copy = source.simulator()
    assert copy is not source.trained
    pairs = zip(copy.parameters(), source.trained.parameters(), strict=True)
    assert all(torch.equal(a, b) for a, b in pairs)
    assert source.simulator("random", {"network": {"M": 2}}).M == 2
    assert (source.weights_label("trained"), source.weights_label("random")) == (
        "a run",
        "random weights",
    )
    with pytest.raises(BenchError, match="architecture is its own"):
        source.simulator("trained", {"network": {"M": 2}})
    with pytest.raises(BenchError, match="weights must be trained or random"):
        source.simulator("other")


def test_the_learned_settings_set_their_knobs_on_copies():
    source = _tiny_source(trained=True)
    own = source.trained.contacts.contact_passes
    c = OmegaConf.create(
        {
            "learned_settings": {
                "as_trained": {},
                "passes0": {"contact_passes": 0},
                "constraints3": {"constraints": 3},
                "threads2": {"threads": 2},
            }
        }
    )
    settings = {s.name: s for s in crossover.learned_settings(c, source, threads=1)}
    knobs = {name: s.knobs for name, s in settings.items()}
    base = {"contact_passes": own, "constraints": 0, "compile": False, "threads": 1}
    assert knobs == {
        "as_trained": base,
        "passes0": base | {"contact_passes": 0},
        "constraints3": base | {"constraints": 3},
        "threads2": base | {"threads": 2},
    }
    assert settings["passes0"].sim.contacts.contact_passes == 0
    assert source.trained.contacts.contact_passes == own  # the trained model itself unchanged
    assert isinstance(settings["constraints3"].sim, ConstrainedSimulator)
    assert settings["constraints3"].sim.iterations == 3
    bad = OmegaConf.create({"learned_settings": {"x": {"passes": 1}}})
    with pytest.raises(BenchError, match="unknown knob passes"):
        crossover.learned_settings(bad, source, threads=2)


def test_the_shipped_weights_are_the_bench_default_source():
    cfg = _cfg()
    assert cfg.run == "pretrained" and quick_config(cfg).run is None
    source = learned_source(cfg, stats={})
    assert source.label == "pretrained" and source.trained is not None
    assert source.model.network.M == source.trained.M
    [passes0] = crossover.learned_settings(
        OmegaConf.create({"learned_settings": {"passes0": {"contact_passes": 0}}}), source, 1
    )
    assert passes0.sim.contacts.contact_passes == 0 != source.trained.contacts.contact_passes


def test_quick_bench_runs_the_crossover_over_draws_and_windows(quick):
    out, result = quick
    cross = result["crossover"]
    assert (cross["run"], cross["draws"]) == ("random weights", 2)
    assert [(c["window"], c["n_spheres"]) for c in cross["cases"]] == [
        ("in_motion", 10),
        ("landed", 10),
    ]
    assert cross["settings"]["passes0"]["contact_passes"] == 0
    names = ["learned as_trained", "learned passes0", "pybullet-1", "pybullet-2"]
    for case in cross["cases"]:
        assert [p["simulator"] for p in case["points"]] == names
        assert [[r["simulator"] for r in rows] for rows in case["draws"]] == [names, names]
        assert all(r["fps"] > 0 and r["mse20"] is not None for r in case["draws"][0])
        assert case["points"] == summary(case["draws"])
        assert case == {**case, **judged(case["points"])}
    for window in ("in_motion", "landed"):
        cases = [c for c in cross["cases"] if c["window"] == window]
        assert cross["front_from"][window] == front_from(cases)
    md = (out / "bench.md").read_text()
    assert "## Crossover: the trained model against pybullet on the same work" in md
    assert crossover_table.headline(cross, "landed") in md
    assert crossover_table.fronts_line(cross, "in_motion") in md


def test_the_default_bench_keeps_to_medium_sizes_and_large_adds_the_rest():
    default, large = merged_config(_cfg()), merged_config(_cfg("large=true"))
    assert max(default.sizes) == max(default.crossover.sizes) == 1000
    assert max(large.sizes) == max(large.crossover.sizes) == 10000
    assert large.crossover.draws > default.crossover.draws
    # large merges key by key: the default settings stay, the compiled point is added
    assert list(large.crossover.learned_settings) == [
        *default.crossover.learned_settings,
        "compiled",
    ]
    assert large.learned.configs.constraints.weights == "trained"
    assert merged_config(_cfg("quick=true", "crossover=null")).crossover is None


def test_a_key_set_alone_on_the_command_line_wins_over_the_quick_settings():
    given = ["quick=true", "run=pretrained", "sizes=[154]", "crossover.draws=1"]
    cfg = merged_config(_cfg(*given), given)
    assert cfg.run == "pretrained" and list(cfg.sizes) == [154] and cfg.crossover.draws == 1
    assert list(cfg.crossover.sizes) == [10]  # the rest of the quick settings stay
    assert merged_config(_cfg("quick=true")).run is None  # quick alone: random weights


# ------------------------------------------------------------------- pybullet's bench curve
def test_bench_curve_points_pair_each_substep_count_with_its_rate(tmp_path):
    bench = {"pybullet": [{"n_spheres": 154, "substeps": s, "fps": 50.0 * s} for s in (1, 5)]}
    extra = {
        "pybullet_accuracy": [
            {"n_spheres": 154, "substeps": 5, "mse": 0.2},
            {"n_spheres": 154, "substeps": 1, "mse": 0.5},
            {"n_spheres": 154, "substeps": 400, "mse": None},  # the reference: no point
        ]
    }
    pts = pareto.pybullet_points(bench, extra, "mse")
    got = [(p.ms_per_frame, p.error, p.kind) for p in pts]
    assert got == [(4.0, 0.2, "pybullet"), (20.0, 0.5, "pybullet")]
    path = pareto.bench_figure(tmp_path / "curve.png", bench, extra)
    assert path.stat().st_size > 1000


def test_training_profile_splits_one_step_into_its_parts(quick):
    out, _ = quick
    p = json.loads((out / "bench_extra.json").read_text())["profile"]
    parts = ("data", "noise", "push_forward", "graph", "forward", "backward", "optimiser")
    assert all(p[f"{k}_ms"] > 0 for k in parts)  # quick: one push-forward step, noise on
    assert sum(p[f"{k}_ms"] for k in parts) == pytest.approx(p["step_ms"])
    assert sum(p[f"{k}_share"] for k in parts) == pytest.approx(1.0)
    assert p["pairs_per_s"] == pytest.approx(p["batch_size"] / (p["step_ms"] / 1000))
    assert p["gflops"] == pytest.approx(p["gflop_per_step"] / (p["step_ms"] / 1000))
    machine = json.loads((out / "bench.json").read_text())["machine"]
    assert p["share_of_matmul"] == pytest.approx(p["gflops"] / machine["matmul_gflops"])
    text = (out / "bench.md").read_text()
    assert "Where a training step's time goes" in text and "| push-forward |" in text


def test_the_gpu_section_runs_on_any_device():
    cfg = _cfg("quick=true", "gpu.device=cpu")
    cfg = quick_config(cfg)
    rng = np.random.default_rng(0)
    trajectories = bench_scenes.training_trajectories(cfg, rng)
    runs = {10: {"traj": bench_scenes.bench_run(cfg, 10, rng)}}
    out = gpu_section(cfg, trajectories, compute_stats(trajectories), runs)
    assert [r["variant"] for r in out["training"]] == ["eager", "tf32", "bf16"]
    for row in out["training"]:
        assert row["steps_per_s"] > 0 and row["nodes_per_s"] > row["steps_per_s"]
        assert row["batch_size"] == 4 and row["peak_mib"] is None  # no CUDA memory here
    [frame] = out["rollout"]
    assert frame["n_spheres"] == 10 and frame["variant"] == "eager" and frame["fps"] > 0
    assert "| bf16 |" in "\n".join(gpu_tables({"gpu": out}))
    assert torch.get_float32_matmul_precision() == "highest"  # restored after the tf32 row


@pytest.mark.slow
def test_the_gpu_sections_compiled_rows_run_on_any_device():
    """The compiled training and rollout rows (inductor, as on a GPU) run, here on the CPU."""
    cfg = quick_config(_cfg("quick=true", "gpu.device=cpu"))
    cfg.gpu.variants, cfg.gpu.rollout_variants = ["compiled"], ["compiled"]
    rng = np.random.default_rng(0)
    trajectories = bench_scenes.training_trajectories(cfg, rng)
    runs = {10: {"traj": bench_scenes.bench_run(cfg, 10, rng)}}
    out = gpu_section(cfg, trajectories, compute_stats(trajectories), runs)
    [row], [frame] = out["training"], out["rollout"]
    assert row["variant"] == "compiled" and row["steps_per_s"] > 0, row
    assert frame["variant"] == "compiled" and frame["fps"] > 0, frame
    assert "| 10 | compiled |" in "\n".join(gpu_tables({"gpu": out}))


def test_a_failing_gpu_row_is_reported_not_fatal(monkeypatch):
    cfg = quick_config(_cfg("quick=true", "gpu.device=cpu"))
    cfg.gpu.variants = ["eager"]
    monkeypatch.setattr(gpu_module, "training_row", lambda *a: 1 / 0)
    rng = np.random.default_rng(0)
    trajectories = bench_scenes.training_trajectories(cfg, rng)
    out = gpu_section(cfg, trajectories, compute_stats(trajectories), {})
    assert out["training"] == [{"variant": "eager", "error": "ZeroDivisionError: division by zero"}]
    assert "| eager | failed: ZeroDivisionError" in "\n".join(gpu_tables({"gpu": out}))


def test_cost_linearity_is_judged_between_two_sizes_from_300_spheres():
    def linear(sizes_ms):
        extra = {"learned": [_learned(n, 1000.0 / ms, 0.2, 1.0, 0.5) for n, ms in sizes_ms]}
        return targets({}, extra)[4]

    # the default sizes stop at 1 000: 1 000 against 300 spheres
    assert linear([(154, 5.0), (300, 10.0), (1000, 40.0)])[1:] == ["1.20", "met"]
    assert linear([(154, 5.0), (1000, 40.0)]) == [
        "cost ~ linear",
        "needs two sizes from 300 spheres",
        "not judged",
    ]


@pytest.mark.parametrize("phase", ["interleaved", "profile", "rollout_sizes"])
def test_a_phase_set_to_null_is_refused_in_one_line(tmp_path, phase):
    """Only the crossover may be left out; another phase set to null was a traceback."""
    with pytest.raises(BenchError) as refused:
        bench(_cfg(f"out_dir={tmp_path}", f"{phase}=null"))
    assert str(refused.value) == (
        f"{phase}=null: make bench runs this phase every time; only crossover=null leaves a "
        "phase out (quick=true makes every phase short)"
    )
    assert not tmp_path.joinpath("bench.json").exists()
