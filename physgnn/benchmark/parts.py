"""Measurements of ``make bench`` other than the learned per-frame cost (see :mod:`physgnn.bench`):
the machine, bench scenes and timed pybullet runs, training throughput, cost versus activity."""

from __future__ import annotations

import dataclasses
import os
import platform
import time

import lightning as L
import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from torch.utils.data import RandomSampler
from torch_geometric.loader import DataLoader

from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import arena_planes, build_scene, materials_array
from physgnn.physics.scene import GROUND, Effects, Scene
from physgnn.training.datamodule import PairDataset


# ------------------------------------------------------------------------------------ machine
def cpu_name() -> str:
    """CPU model from /proc/cpuinfo (Linux), else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def matmul_gflops(m: int, k: int, n: int, repeats: int) -> float:
    """Best fp32 rate (GFLOP/s) of ``[m, k] @ [k, n]`` over ``repeats`` products."""
    a, b = torch.randn(m, k), torch.randn(k, n)
    out = torch.empty(m, n)
    torch.matmul(a, b, out=out)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        torch.matmul(a, b, out=out)
        best = min(best, time.perf_counter() - t0)
    return 2 * m * k * n / best / 1e9


def machine_info(threads: int, shapes, repeats: int) -> dict:
    """CPU, torch threads, and the fp32 matmul rate: the best over ``shapes`` ([m, k, n]);
    also the rate of the first shape on one thread (to see whether the threads really run in
    parallel or the cores are busy with other work)."""
    rates = {f"{m}x{k}x{n}": matmul_gflops(m, k, n, repeats) for m, k, n in shapes}
    torch.set_num_threads(1)
    m, k, n = shapes[0]
    one_thread = matmul_gflops(m, k, n, repeats)
    torch.set_num_threads(threads)
    return {
        "cpu": cpu_name(),
        "threads": torch.get_num_threads(),
        "requested_threads": threads,
        "matmul_gflops": max(rates.values()),
        "matmul_by_shape": rates,
        "matmul_gflops_1_thread": one_thread,
        "torch": torch.__version__,
        "python": platform.python_version(),
        "loadavg_start": os.getloadavg()[0],
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", "unset (spin, then sleep)"),
    }


# ------------------------------------------------------------------------------------- scenes
def bench_scene(
    scene_cfg: DictConfig,
    n: int,
    rng: np.random.Generator,
    area_per_sphere: float,
    h_max: float,
    n_frames: int,
) -> Scene:
    """random_box with exactly ``n`` spheres on a floor of ``n · area_per_sphere`` m²."""
    side = float(np.sqrt(n * area_per_sphere))
    over = {
        "n_min": n,
        "n_max": n,
        "side_min": side,
        "side_max": side,
        "h_max": h_max,
        "n_frames": n_frames,
    }
    return build_scene(OmegaConf.merge(scene_cfg, over), rng)


def scene_from_frame(scene: Scene, traj, t: int, n_frames: int) -> Scene:
    """``scene`` restarted from frame ``t`` of its trajectory (engine velocities)."""
    return dataclasses.replace(
        scene,
        pos=traj.pos[t],
        quat=traj.quat[t],
        vel=traj.vel[t],
        angvel=traj.angvel[t],
        n_frames=n_frames,
    ).validate()


def with_frames(scene: Scene, n_frames: int) -> Scene:
    return dataclasses.replace(scene, n_frames=n_frames)


def timed_pybullet(scene: Scene, engine: dict, repeats: int = 1) -> tuple[object, float]:
    """``(trajectory, frames per second)``, best of ``repeats`` runs. The set-up (creating the
    bodies) is timed on a one-frame, one-substep run of the same scene and subtracted."""
    setup = total = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        simulate(with_frames(scene, 2), {**engine, "substeps": 1})
        setup = min(setup, time.perf_counter() - t0)
        t0 = time.perf_counter()
        traj = simulate(scene, engine)
        total = min(total, time.perf_counter() - t0)
    stepping = total - setup
    if stepping < 0.1 * total:  # set-up noise swamps the stepping: count it (a lower bound)
        print(
            f"warning: pybullet set-up ({setup:.3g} s) dominates the timed run "
            f"({total:.3g} s); FPS includes it",
            flush=True,
        )
        stepping = total
    return traj, (scene.n_frames - 1) / stepping


def pybullet_frames(n: int, frames: int, sphere_frames: int) -> int:
    """Timed frames for ``n`` spheres: at least ``frames``, more for small scenes so that
    stepping, not set-up, dominates the timed run."""
    return max(int(frames), int(sphere_frames) // max(n, 1))


# ----------------------------------------------------------------------------------- training
def training_trajectories(cfg: DictConfig, rng: np.random.Generator) -> list:
    """A few random_box trajectories (the scene config, ``training.n_frames`` frames)."""
    scene_cfg = OmegaConf.merge(cfg.scene, {"n_frames": cfg.training.n_frames})
    engine = OmegaConf.to_container(cfg.engine)
    return [simulate(build_scene(scene_cfg, rng), engine) for _ in range(cfg.training.trajectories)]


class ThroughputTimer(L.Callback):
    """State pairs and nodes per second over the training batches after ``warmup``."""

    def __init__(self, warmup: int):
        self.warmup = warmup
        self.t0 = self.t1 = None
        self.pairs = self.nodes = self.steps = 0

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
        if batch_idx == self.warmup:
            self.t0 = time.perf_counter()

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
        if batch_idx >= self.warmup:
            self.t1 = time.perf_counter()
            self.pairs += batch.num_graphs
            self.nodes += batch.num_nodes
            self.steps += 1


def training_throughput(cfg: DictConfig, trajectories: list, stats: dict) -> dict:
    """Baseline training (Lightning, Adam, noise) for ``training.steps`` batches; pairs/s and
    nodes/s after ``warmup_steps`` (data loading included)."""
    c = cfg.training
    simulator = instantiate(cfg.model, stats=stats)
    lit = instantiate(c.lit, simulator=simulator)
    data = PairDataset(trajectories, simulator.H)
    sampler = RandomSampler(
        data,
        replacement=True,
        num_samples=c.steps * c.batch_size,
        generator=torch.Generator().manual_seed(int(cfg.seed)),
    )
    loader = DataLoader(data, batch_size=c.batch_size, sampler=sampler)
    timer = ThroughputTimer(min(c.warmup_steps, c.steps - 1))
    trainer = L.Trainer(
        accelerator="cpu",
        devices=1,
        max_steps=c.steps,
        max_epochs=1,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        num_sanity_val_steps=0,
        limit_val_batches=0,
        callbacks=[timer],
    )
    trainer.fit(lit, train_dataloaders=loader)
    secs = max(timer.t1 - timer.t0, 1e-9)
    out = {
        "pairs_per_s": timer.pairs / secs,
        "nodes_per_s": timer.nodes / secs,
        "steps_timed": timer.steps,
        "batch_size": int(c.batch_size),
        "mean_nodes_per_pair": timer.nodes / max(timer.pairs, 1),
        "seconds": secs,
    }
    print(
        f"training: {out['pairs_per_s']:.0f} pairs/s, {out['nodes_per_s']:.0f} nodes/s", flush=True
    )
    return out


# ----------------------------------------------------------------------------------- activity
def without_walls(traj):
    """The trajectory with only its ground plane (the spheres' motion unchanged)."""
    keep = np.asarray(traj.plane_kind) == GROUND
    return dataclasses.replace(traj, planes=traj.planes[keep], plane_kind=traj.plane_kind[keep])


def with_effects(traj, **changes):
    return dataclasses.replace(traj, effects=dataclasses.replace(traj.effects, **changes))


def resting_scene(scene_cfg: DictConfig, resting: int, moving: int, rng, n_frames: int) -> Scene:
    """``resting`` spheres of the smallest radius on a square grid, at rest on the ground one
    radius apart, and ``moving`` spheres thrown across the arena just above them."""
    c = OmegaConf.to_container(scene_cfg, resolve=True)
    r = float(c["radius_min"])
    k = int(np.ceil(np.sqrt(resting)))
    side = 3 * r * k + 4 * r
    g = (np.arange(k) - (k - 1) / 2) * 3 * r
    gx, gy = np.meshgrid(g, g, indexing="ij")
    rest = np.stack([gx.ravel(), gy.ravel(), np.full(k * k, r)], 1)[:resting]
    xy = rng.uniform(-side / 3, side / 3, (moving, 2))
    fly = np.concatenate([xy, (4 + 3 * np.arange(moving))[:, None] * r], 1)
    n = resting + moving
    vel = np.zeros((n, 3))
    vel[resting:, :2] = rng.normal(0, 3, (moving, 2))
    planes, kinds = arena_planes(side, c["wall_height"])
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    quat = np.zeros((n, 4))
    quat[:, 0] = 1
    return Scene(
        name="resting_plus_moving",
        radius=f32(np.full(n, r)),
        mass=f32(np.full(n, c["density"] * 4 / 3 * np.pi * r**3)),
        material=np.zeros(n, dtype=np.int64),
        pos=f32(np.concatenate([rest, fly])),
        quat=f32(quat),
        vel=f32(vel),
        angvel=f32(np.zeros((n, 3))),
        planes=f32(planes),
        plane_kind=kinds,
        materials=materials_array(c["materials"]),
        dt=float(c["dt"]),
        n_frames=n_frames,
        effects=Effects.from_dict(c.get("effects")),
    ).validate()


def activity_rows(cfg: DictConfig, runs: dict, stats: dict, rng) -> list[dict]:
    """Baseline ms per frame for the cases of issue 7 item 3 (one row per case), all timed
    together (:func:`physgnn.bench.time_cases`)."""
    from physgnn.benchmark.run import frame_states, make_simulator, time_cases
    from physgnn.models.sleeping import SleepingSimulator

    a = cfg.activity
    sim = make_simulator(cfg.model, {}, stats)
    base = runs[a.n_spheres]["traj"]
    engine = OmegaConf.to_container(cfg.engine)
    n_frames = sim.H + a.sleep_k + a.frames + 1
    mixed = simulate(resting_scene(cfg.scene, a.resting, a.moving, rng, n_frames), engine)
    mixed_states = frame_states(mixed, sim.H)
    sleeper = SleepingSimulator(sim, k=a.sleep_k)
    for s in mixed_states[: a.sleep_k + 1]:
        sleeper(s)
    asleep = int(sleeper.asleep.sum())
    n_all = a.resting + a.moving
    mix = f"{a.resting} resting + {a.moving} moving"
    cases = [
        ("contacts on", sim, base),
        ("contacts off (no sphere_contact)", sim, with_effects(base, sphere_contact=False)),
        ("walls", sim, base),
        ("no walls (ground only)", sim, without_walls(base)),
        (f"{mix}, sleeping on ({asleep} asleep)", sleeper, mixed_states[a.sleep_k + 1 :]),
        (f"{mix}, sleeping off", sim, mixed_states),
        (f"{n_all} moving", sim, bench_run(cfg, n_all, rng)),
    ]
    timed = [(s, x if isinstance(x, list) else frame_states(x, sim.H)) for _, s, x in cases]
    rows = []
    for (label, _, _), (_, states), t in zip(
        cases, timed, time_cases(timed, a.rounds), strict=True
    ):
        rows.append({"case": label, "n_spheres": int(states[0].pos.shape[0]), **_brief(t)})
        print(f"activity {label:45s}: {t['total_ms']:8.2f} ms/frame", flush=True)
    return rows


def bench_run(cfg: DictConfig, n: int, rng):
    """A bench scene of ``n`` spheres in motion: the pybullet frames after the warm-up."""
    engine = OmegaConf.to_container(cfg.engine)
    scene = bench_scene(
        cfg.scene, n, rng, cfg.area_per_sphere, cfg.h_max, cfg.warmup_frames + cfg.frames + 1
    )
    traj = simulate(scene, engine)
    start = cfg.warmup_frames
    return dataclasses.replace(
        traj,
        pos=traj.pos[start:],
        quat=traj.quat[start:],
        vel=traj.vel[start:],
        angvel=traj.angvel[start:],
    )


def rollout_rows(cfg: DictConfig, runs: dict, stats: dict) -> list[dict]:
    """The baseline through :func:`physgnn.rollout.rollout` (the path ``make eval`` times) on
    the bench scenes of ``rollout_sizes``: FPS and ms per frame of each part."""
    from physgnn.benchmark.run import make_simulator
    from physgnn.rollout import rollout

    sim = make_simulator(cfg.model, {}, stats)
    rows = []
    for n in cfg.rollout_sizes:
        traj = runs[n]["traj"]
        rollout(sim, [traj], n_frames=sim.H + 2)  # warm-up
        sim.reset_timings()
        [res] = rollout(sim, [traj], n_frames=traj.n_frames)
        t = res.timings
        steps = max(t["steps"], 1)
        ms = {k: 1000 * t[k] / steps for k in ("graph", "network", "integration", "total")}
        rows.append(
            {
                "n_spheres": n,
                "frames": steps,
                "fps": res.fps,
                **{f"{k}_ms": v for k, v in ms.items()},
            }
        )
        print(f"rollout n={n:6d}: {res.fps:8.2f} FPS", flush=True)
    return rows


def _brief(t: dict) -> dict:
    return {
        k: t[k]
        for k in (
            "total_ms",
            "graph_ms",
            "network_ms",
            "integrate_ms",
            "pp_edges",
            "ps_edges",
            "nodes",
        )
    }
