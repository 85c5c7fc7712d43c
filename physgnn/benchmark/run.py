"""``python -m physgnn.bench`` (``make bench``): what accuracy costs in time, in one run.

Measures the machine (CPU, threads, fp32 matmul rate), the learned simulator per configuration
and scene size (ms per frame split into graph / network / integration, FPS, FLOPs and the share
of the matmul rate), pybullet on the same scenes (FPS at 10 substeps; at one size, FPS and
accuracy against a fine reference for several substep counts), the training throughput of the
baseline and the cost of idle spheres, contacts and walls (issue 7). Writes
``bench.json`` (the keys of issue 5), ``bench_extra.json`` (everything else) and ``bench.md``.

Scenes are random_box scenes in motion: pybullet runs ``warmup_frames`` from the initial
state, and the timed frames start from there, so learned steps (one step per ground-truth
frame, random weights) see the contacts of a real pile. Weights do not change the cost.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from torch_geometric.data import Batch

from physgnn.benchmark import parts
from physgnn.benchmark.markdown import write_markdown
from physgnn.data.dataset import compute_stats
from physgnn.data.state import TrajectoryFrames
from physgnn.errors import ConfigError
from physgnn.groundtruth.engine import simulate
from physgnn.metrics import PENETRATION_KEYS
from physgnn.physics.integrator import euler_step


class BenchError(ConfigError):
    """A bench setting that cannot be run (one-line message)."""


# ------------------------------------------------------------------------------ learned steps
def make_simulator(model_cfg: DictConfig, overrides: dict, stats: dict):
    """The model of ``model_cfg`` with ``overrides`` (constructor keys), random weights."""
    cfg = OmegaConf.merge(model_cfg, overrides)
    sim = instantiate(cfg, stats=stats).eval()
    sim.effects_trained.fill_(True)  # as if trained on every effect: no rollout warning
    return sim


def frame_states(traj, H: int, copies: int = 1) -> list:
    """Batches of every frame ``t ≥ H`` of a trajectory (targets dropped), each holding
    ``copies`` copies of the scene (disconnected graphs, as a batched rollout)."""
    frames = TrajectoryFrames(traj)
    states = []
    for t in range(H, frames.n_frames):
        s = frames.state(t, H)
        s.target_vel = s.target_angvel = None
        states.append(Batch.from_data_list([s] * copies))
    return states


class GraphRecorder:
    """Wraps a simulator's graph builder to keep the last graph and its node count."""

    def __init__(self, builder):
        self.builder = builder
        self.last = None

    def __getattr__(self, name):
        if name == "builder":
            raise AttributeError(name)
        return getattr(self.builder, name)

    def __call__(self, state):
        graph = self.builder(state)
        self.last = (state.pos.shape[0], graph)
        return graph


def recorder_of(sim) -> GraphRecorder:
    """The :class:`GraphRecorder` of ``sim`` (or of the simulator it wraps), installed once."""
    inner = getattr(sim, "simulator", sim)
    if not isinstance(inner.graph_builder, GraphRecorder):
        inner.graph_builder = GraphRecorder(inner.graph_builder)
    return inner.graph_builder


@torch.inference_mode()
def step_once(sim, state) -> tuple[dict, tuple | None]:
    """One learned step on ``state`` (prediction, integration, history shift): seconds of
    each part and ``(nodes, graph)`` the network ran on (None when it did not run)."""
    recorder = recorder_of(sim)
    recorder.last = None
    sim.reset_timings()
    t0 = time.perf_counter()
    vel, angvel = sim(state)
    t1 = time.perf_counter()
    pos, quat = euler_step(state.pos, state.quat, vel, angvel, state.scene_dt, sim.rotating(state))
    if hasattr(sim, "hold"):
        pos, quat = sim.hold(state.pos, state.quat, pos, quat)
    _ = (
        torch.cat([vel[:, None], state.vel[:, :-1]], 1),
        torch.cat([angvel[:, None], state.angvel[:, :-1]], 1),
        pos,
        quat,
    )
    t2 = time.perf_counter()
    secs = {
        "graph": sim.timings["graph"],
        "network": sim.timings["network"],
        "integrate": t2 - t1,
        "total": t2 - t0,
    }
    return secs, recorder.last


def time_cases(cases: list[tuple], repeats: int) -> list[dict]:
    """Per-frame cost of each ``(sim, states)`` case over ``repeats`` rounds; a round runs one
    step of every case (cycling over its states), so a busy spell of the machine hits all the
    cases alike. Per case: ms of graph / network / integration / total averaged over its
    fastest half of the steps (robust, and the parts add up), fps, mean node / edge counts and
    the network's GFLOP per step (``flops_per_step`` of the graphs it ran on)."""
    logs = []
    for sim, states in cases:
        step_once(sim, states[0])  # warm-up
        logs.append(
            {
                "graph": [],
                "network": [],
                "integrate": [],
                "total": [],
                "flop": 0,
                "nodes": 0,
                "pp": 0,
                "ps": 0,
            }
        )
    for k in range(repeats):
        for (sim, states), log in zip(cases, logs, strict=True):
            step, ran = step_once(sim, states[k % len(states)])
            for key in ("graph", "network", "integrate", "total"):
                log[key].append(step[key])
            if ran is not None:
                n, graph = ran
                e, f = graph.pp_index.shape[1], graph.ps_index.shape[1]
                log["flop"] += sim.network.flops_per_step(n, e, f)
                log["nodes"], log["pp"], log["ps"] = log["nodes"] + n, log["pp"] + e, log["ps"] + f
    return [_summary(log, repeats) for log in logs]


def _summary(log: dict, repeats: int) -> dict:
    fast = np.argsort(log["total"])[: max(repeats // 2, 1)]
    ms = {
        k: 1000 * float(np.mean(np.asarray(log[k])[fast]))
        for k in ("graph", "network", "integrate", "total")
    }
    return {
        "graph_ms": ms["graph"],
        "network_ms": ms["network"],
        "integrate_ms": ms["integrate"],
        "total_ms": ms["total"],
        "fps": 1000 / ms["total"],
        "gflop_per_step": log["flop"] / repeats / 1e9,
        "network_flop": log["flop"],
        "nodes": log["nodes"] / repeats,
        "pp_edges": log["pp"] / repeats,
        "ps_edges": log["ps"] / repeats,
        "repeats": repeats,
    }


def time_learned(sim, states: list, repeats: int) -> dict:
    """:func:`time_cases` of one case."""
    return time_cases([(sim, states)], repeats)[0]


def batched_rows(cfg: DictConfig, runs: dict, stats: dict) -> list[dict]:
    """The baseline on ``batched.scenes`` copies of one scene in one graph: cost per scene
    (the batch sizes are timed together, :func:`time_cases`)."""
    sim = make_simulator(cfg.model, {}, stats)
    n, sizes = cfg.batched.n_spheres, list(cfg.batched.scenes)
    cases = [(sim, frame_states(runs[n]["traj"], sim.H, copies=b)) for b in sizes]
    rows = []
    for b, t in zip(sizes, time_cases(cases, repeats_for(n, cfg.learned)), strict=True):
        per_scene = t["total_ms"] / b
        rows.append(
            {
                "n_spheres": n,
                "scenes": b,
                "batch_ms": t["total_ms"],
                "ms_per_scene": per_scene,
                "scene_fps": 1000 / per_scene,
                "gflop_per_step": t["gflop_per_step"],
            }
        )
        print(f"batched {b:3d} x {n} spheres: {per_scene:8.2f} ms per scene-frame", flush=True)
    return rows


def repeats_for(n: int, c: DictConfig) -> int:
    return int(min(max(c.sphere_frames // max(n, 1), c.min_repeats), c.max_repeats))


def learned_rows(cfg: DictConfig, runs: dict, stats: dict, matmul_gflops: float) -> list[dict]:
    """Every configuration on every size it asks for (``runs[n]`` = pybullet run of size n);
    the configurations of one size are timed together (:func:`time_cases`)."""
    sims, sizes = {}, {}
    for name, c in cfg.learned.configs.items():
        sims[name] = make_simulator(cfg.model, OmegaConf.to_container(c.overrides), stats)
        sizes[name] = list(cfg.sizes) if c.sizes is None else list(c.sizes)
    rows = {}
    for n in sorted({n for s in sizes.values() for n in s}):
        names = [name for name in sims if n in sizes[name]]
        states = {h: frame_states(runs[n]["traj"], h) for h in {sims[k].H for k in names}}
        cases = [(sims[k], states[sims[k].H]) for k in names]
        for name, t in zip(names, time_cases(cases, repeats_for(n, cfg.learned)), strict=True):
            rate = t["gflop_per_step"] / max(t["network_ms"] / 1000, 1e-12)
            rows[name, n] = {
                "config": name,
                "n_spheres": n,
                **t,
                "share_of_matmul": rate / matmul_gflops,
            }
            print(
                f"learned {name:9s} n={n:6d}: {t['total_ms']:8.2f} ms/frame "
                f"(graph {t['graph_ms']:.2f}, network {t['network_ms']:.2f}), "
                f"{rate:.1f} GFLOP/s",
                flush=True,
            )
    return [rows[name, n] for name in sims for n in sizes[name]]


# ---------------------------------------------------------------------------------- pybullet
def pybullet_runs(cfg: DictConfig, rng: np.random.Generator) -> dict:
    """For each size: the start scene (after warm-up), the timed trajectory and its FPS."""
    runs = {}
    sizes = {
        cfg.accuracy.n_spheres,
        cfg.activity.n_spheres,
        cfg.batched.n_spheres,
        *cfg.sizes,
        *cfg.rollout_sizes,
    }
    for c in cfg.learned.configs.values():
        sizes |= set(c.sizes or [])
    sizes = sorted(sizes)
    engine = OmegaConf.to_container(cfg.engine)
    for n in sizes:
        scene = parts.bench_scene(
            cfg.scene, n, rng, cfg.area_per_sphere, cfg.h_max, cfg.warmup_frames + 1
        )
        warm = simulate(scene, engine)
        frames = parts.pybullet_frames(n, cfg.frames, cfg.pybullet_sphere_frames)
        start = parts.scene_from_frame(scene, warm, -1, frames + 1)
        traj, fps = parts.timed_pybullet(start, engine, cfg.pybullet_repeats if n <= 1000 else 1)
        runs[n] = {"start": start, "traj": traj, "fps": fps}
        print(f"pybullet n={n:6d}: {fps:8.2f} FPS ({engine['substeps']} substeps)", flush=True)
    return runs


def accuracy_sweep(cfg: DictConfig, start) -> list[dict]:
    """pybullet at each substep count from ``start``: FPS and accuracy vs the reference."""
    from physgnn import metrics

    engine = OmegaConf.to_container(cfg.engine)
    scene = parts.with_frames(start, cfg.accuracy.frames + 1)
    ref = simulate(scene, {**engine, "substeps": cfg.accuracy.reference_substeps})
    ref_dict = metrics.trajectory_dict(ref)
    rows = [
        {
            "substeps": cfg.accuracy.reference_substeps,
            "reference": True,
            "fps": None,
            **_physics(metrics.trajectory_metrics(ref_dict)),
        }
    ]
    for substeps in cfg.accuracy.substeps:
        traj, fps = parts.timed_pybullet(
            scene, {**engine, "substeps": substeps}, cfg.pybullet_repeats
        )
        m = metrics.trajectory_metrics(metrics.trajectory_dict(traj), ref, horizon=5)
        rows.append(
            {
                "substeps": substeps,
                "reference": False,
                "fps": fps,
                "mse": m["mse"],
                "mse5": m["mse5"],
                "chamfer": m["chamfer"],
                **_physics(m),
            }
        )
        print(f"pybullet {substeps:4d} substeps: {fps:8.2f} FPS, mse {m['mse']:.3e}", flush=True)
    for row in rows:
        row["n_spheres"] = start.n_spheres
    return rows


def _physics(m: dict) -> dict:
    return {k: m[k] for k in ("energy_gain", *PENETRATION_KEYS)}


def pybullet_rows(cfg: DictConfig, runs: dict, sweep: list[dict]) -> list[dict]:
    """bench.json's pybullet list: every size at the engine's substeps, the sweep's size at
    each substep count (with its accuracy)."""
    n_acc = cfg.accuracy.n_spheres
    rows = [
        {
            "n_spheres": n,
            "substeps": int(cfg.engine.substeps),
            "fps": runs[n]["fps"],
            "mse_vs_reference": None,
        }
        for n in cfg.sizes
        if n != n_acc
    ]
    rows += [
        {
            "n_spheres": r["n_spheres"],
            "substeps": r["substeps"],
            "fps": r["fps"],
            "mse_vs_reference": r["mse"],
        }
        for r in sweep
        if not r["reference"]
    ]
    if n_acc in cfg.sizes and cfg.engine.substeps not in cfg.accuracy.substeps:
        rows.append(
            {
                "n_spheres": n_acc,
                "substeps": int(cfg.engine.substeps),
                "fps": runs[n_acc]["fps"],
                "mse_vs_reference": None,
            }
        )
    return sorted(rows, key=lambda r: (r["n_spheres"], r["substeps"]))


# -------------------------------------------------------------------------------------- bench
def bench(cfg: DictConfig) -> dict:
    """Run every measurement of ``cfg`` (see ``conf/bench.yaml``); returns bench.json's dict."""
    if cfg.quick:
        cfg = quick_config(cfg)
    if int(cfg.threads) < 1:
        raise BenchError(f"threads must be >= 1 (got {cfg.threads})")
    torch.set_num_threads(int(cfg.threads))
    torch.manual_seed(int(cfg.seed))
    rng = np.random.default_rng(int(cfg.seed))
    start = time.perf_counter()
    machine = parts.machine_info(int(cfg.threads), cfg.machine.shapes, cfg.machine.repeats)
    print(
        f"machine: {machine['cpu']}, {machine['threads']} threads, "
        f"{machine['matmul_gflops']:.1f} GFLOP/s",
        flush=True,
    )
    phases: dict[str, float] = {}

    def timed(name: str, fn, *args):
        t0 = time.perf_counter()
        out = fn(*args)
        phases[name] = time.perf_counter() - t0
        return out

    train_trajs = timed("training data", parts.training_trajectories, cfg, rng)
    stats = compute_stats(train_trajs)
    runs = timed("pybullet sizes", pybullet_runs, cfg, rng)
    learned = timed("learned", learned_rows, cfg, runs, stats, machine["matmul_gflops"])
    sweep = timed("pybullet substeps", accuracy_sweep, cfg, runs[cfg.accuracy.n_spheres]["start"])
    training = timed("training", parts.training_throughput, cfg, train_trajs, stats)
    activity = timed("activity", parts.activity_rows, cfg, runs, stats, rng)
    rollouts = timed("rollout", parts.rollout_rows, cfg, runs, stats)
    batched = timed("batched", batched_rows, cfg, runs, stats)
    result = {
        "machine": {k: machine[k] for k in ("cpu", "threads", "matmul_gflops")},
        "learned": [{k: r[k] for k in LEARNED_KEYS} for r in learned],
        "pybullet": pybullet_rows(cfg, runs, sweep),
        "training": {k: training[k] for k in ("pairs_per_s", "nodes_per_s")},
    }
    extra = {
        "machine": machine,
        "learned": learned,
        "pybullet_accuracy": sweep,
        "training": training,
        "activity": activity,
        "rollout": rollouts,
        "batched": batched,
        "settings": OmegaConf.to_container(cfg, resolve=True),
        "wall_s": time.perf_counter() - start,
        "phase_s": phases,
        "loadavg_end": os.getloadavg()[0],
    }
    write_outputs(Path(cfg.out_dir), result, extra)
    print(f"bench: {extra['wall_s']:.0f} s; wrote {Path(cfg.out_dir) / 'bench.md'}", flush=True)
    return result


def quick_config(cfg: DictConfig) -> DictConfig:
    """``cfg`` with ``quick_settings`` merged over it; its list of configurations replaces
    the full one (not merged into it)."""
    cfg = cfg.copy()
    OmegaConf.set_struct(cfg, False)
    quick = cfg.quick_settings
    if quick.get("learned", {}).get("configs") is not None:
        cfg.learned.configs = quick.learned.configs
    return OmegaConf.merge(cfg, quick)


LEARNED_KEYS = (
    "config",
    "n_spheres",
    "fps",
    "graph_ms",
    "network_ms",
    "integrate_ms",
    "gflop_per_step",
    "share_of_matmul",
)


def write_outputs(out_dir: Path, result: dict, extra: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    _write_json(out_dir / "bench.json", result)
    _write_json(out_dir / "bench_extra.json", extra)
    md = write_markdown(result, extra)
    tmp = out_dir / "bench.md.tmp"
    tmp.write_text(md)
    tmp.replace(out_dir / "bench.md")


def _write_json(path: Path, data: dict) -> None:
    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        return x

    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(clean(data), indent=2) + "\n")
    tmp.replace(path)
