"""Learned steps timed: the model of a config (the trained model of the bench's ``run``, or
random weights for a configuration that changes the architecture: :mod:`.source`), one step
per ground-truth frame, split into graph, network and integration by a
:class:`~physgnn.models.profiling.StepTimer`."""

from __future__ import annotations

import time

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from torch_geometric.data import Batch

from physgnn.benchmark.source import Source
from physgnn.data.state import TrajectoryFrames
from physgnn.models.capture import compile_simulator
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.models.profiling import StepTimer
from physgnn.models.protocol import motion_of
from physgnn.physics import integrator


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


@torch.inference_mode()
def step_once(sim, state) -> tuple[dict, tuple | None]:
    """One learned step on ``state`` (prediction, then
    :func:`physgnn.physics.integrator.step`): seconds of each part and ``(nodes, pp edges,
    ps edges)`` of the graph the network ran on (None when it did not run)."""
    timer = StepTimer()
    t0 = time.perf_counter()
    with timer.watch(sim):
        (vel, angvel), mean = motion_of(timer.predict(sim, state))
    rotate, hold = sim.rotating(state), getattr(sim, "hold", None)
    timer.integrate(
        integrator.step,
        state.pos,
        state.quat,
        state.vel,
        state.angvel,
        vel,
        angvel,
        state.scene_dt,
        rotate,
        hold,
        mean,
    )
    t = timer.timings
    secs = {"graph": t["graph"], "network": t["network"], "integrate": t["integration"]}
    return secs | {"total": time.perf_counter() - t0}, (timer.sizes[-1] if timer.sizes else None)


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
                n, e, f = ran
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


def repeats_for(n: int, c: DictConfig) -> int:
    return int(min(max(c.sphere_frames // max(n, 1), c.min_repeats), c.max_repeats))


def build_simulators(cfg: DictConfig, source: Source) -> dict[str, tuple[object, list[int], str]]:
    """Every configuration of ``cfg.learned.configs``: its simulator (``source``'s, of its
    ``weights``; compiled or followed by the constraint stage when the configuration says so),
    its sizes and what its weights are (the run, or random weights)."""
    sims = {}
    for name, c in cfg.learned.configs.items():
        sim = source.simulator(c.weights, OmegaConf.to_container(c.overrides))
        if c.get("compile"):  # as lit.compile.enabled=true: two regions, dynamic shapes
            compile_simulator(sim)
        if c.get("constraints"):  # the learned step followed by the constraint stage
            sim = ConstrainedSimulator(sim, int(c.constraints))
        sizes = list(cfg.sizes) if c.sizes is None else list(c.sizes)
        sims[name] = sim, sizes, source.weights_label(c.weights)
    return sims


def learned_rows(cfg: DictConfig, runs: dict, sims: dict, matmul_gflops: float) -> list[dict]:
    """Every configuration of ``sims`` (:func:`build_simulators`) on every size it asks for
    (``runs[n]`` = pybullet run of size n); the configurations of one size are timed together
    (:func:`time_cases`)."""
    rows = {}
    for n in sorted({n for _, sizes, _ in sims.values() for n in sizes}):
        names = [name for name, (_, sizes, _) in sims.items() if n in sizes]
        states = {h: frame_states(runs[n]["traj"], h) for h in {sims[k][0].H for k in names}}
        cases = [(sims[k][0], states[sims[k][0].H]) for k in names]
        for name, t in zip(names, time_cases(cases, repeats_for(n, cfg.learned)), strict=True):
            rate = t["gflop_per_step"] / max(t["network_ms"] / 1000, 1e-12)
            rows[name, n] = {
                "config": name,
                "weights": sims[name][2],
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
    return [rows[name, n] for name, (_, sizes, _) in sims.items() for n in sizes]


def batched_rows(cfg: DictConfig, runs: dict, source: Source) -> list[dict]:
    """The trained model (``source``) on ``batched.scenes`` copies of one scene in one graph:
    cost per scene (the batch sizes are timed together, :func:`time_cases`)."""
    sim = source.simulator()
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


def measuring_trainer(max_steps: int, callbacks: list, **options):
    """A one-process CPU ``lightning.Trainer`` for ``max_steps`` timed or counted training
    steps: no logger, checkpoints, progress bar, summary or validation; ``options``: further
    Trainer arguments (e.g. ``gradient_clip_val``)."""
    import lightning as L

    return L.Trainer(
        accelerator="cpu",
        devices=1,
        max_steps=max_steps,
        max_epochs=1,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        num_sanity_val_steps=0,
        limit_val_batches=0,
        callbacks=callbacks,
        **options,
    )
