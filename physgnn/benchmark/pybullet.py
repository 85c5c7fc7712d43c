"""pybullet in the bench: frame rates per size, and accuracy against a fine reference for
several substep counts."""

from __future__ import annotations

import numpy as np
from omegaconf import DictConfig, OmegaConf

from physgnn import metrics
from physgnn.benchmark import scenes
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.oracles import free_fall_error
from physgnn.metrics import PENETRATION_KEYS


def pybullet_runs(cfg: DictConfig, rng: np.random.Generator) -> dict:
    """For each size: the start scene (after warm-up), the timed trajectory and its FPS."""
    runs = {}
    sizes = {
        cfg.accuracy.n_spheres,
        cfg.activity.n_spheres,
        cfg.batched.n_spheres,
        *cfg.sizes,
        *cfg.rollout_sizes,
        *cfg.interleaved.sizes,
    }
    for c in cfg.learned.configs.values():
        sizes |= set(c.sizes or [])
    sizes = sorted(sizes)
    engine = OmegaConf.to_container(cfg.engine)
    for n in sizes:
        scene = scenes.bench_scene(
            cfg.scene, n, rng, cfg.area_per_sphere, cfg.h_max, cfg.warmup_frames + 1
        )
        warm = simulate(scene, engine)
        frames = scenes.pybullet_frames(n, cfg.frames, cfg.pybullet_sphere_frames)
        start = scenes.scene_from_frame(scene, warm, -1, frames + 1)
        traj, fps = scenes.timed_pybullet(start, engine, cfg.pybullet_repeats if n <= 1000 else 1)
        runs[n] = {"start": start, "traj": traj, "fps": fps}
        print(f"pybullet n={n:6d}: {fps:8.2f} FPS ({engine['substeps']} substeps)", flush=True)
    return runs


def accuracy_sweep(cfg: DictConfig, start) -> list[dict]:
    """pybullet at each substep count from ``start``: FPS and accuracy vs the reference, and
    the free-fall error against ½gt² after 4 s
    (:func:`physgnn.groundtruth.oracles.free_fall_error`)."""
    engine = OmegaConf.to_container(cfg.engine)
    scene = scenes.with_frames(start, cfg.accuracy.frames + 1)
    ref = simulate(scene, {**engine, "substeps": cfg.accuracy.reference_substeps})
    rows = [
        {
            "substeps": cfg.accuracy.reference_substeps,
            "reference": True,
            "fps": None,
            "free_fall_error": free_fall_error(cfg.accuracy.reference_substeps),
            **_physics(metrics.trajectory_metrics(ref)),
        }
    ]
    for substeps in cfg.accuracy.substeps:
        traj, fps = scenes.timed_pybullet(
            scene, {**engine, "substeps": substeps}, cfg.pybullet_repeats
        )
        m = metrics.trajectory_metrics(traj, ref, horizon=5)
        rows.append(
            {
                "substeps": substeps,
                "reference": False,
                "fps": fps,
                "free_fall_error": free_fall_error(substeps),
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
