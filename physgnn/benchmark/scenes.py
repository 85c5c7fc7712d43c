"""Bench scenes in motion (random_box with exactly n spheres, after a warm-up) and timed
pybullet runs; variants of them for the activity cases."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from omegaconf import DictConfig, OmegaConf

from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.layouts import arena_planes, materials_array
from physgnn.physics.scene import GROUND, Effects, Scene, as_float32


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


def training_trajectories(cfg: DictConfig, rng: np.random.Generator) -> list:
    """A few random_box trajectories (the scene config, ``training.n_frames`` frames)."""
    scene_cfg = OmegaConf.merge(cfg.scene, {"n_frames": cfg.training.n_frames})
    engine = OmegaConf.to_container(cfg.engine)
    return [simulate(build_scene(scene_cfg, rng), engine) for _ in range(cfg.training.trajectories)]


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
    quat = np.zeros((n, 4))
    quat[:, 0] = 1
    return Scene(
        name="resting_plus_moving",
        radius=as_float32(np.full(n, r)),
        mass=as_float32(np.full(n, c["density"] * 4 / 3 * np.pi * r**3)),
        material=np.zeros(n, dtype=np.int64),
        pos=as_float32(np.concatenate([rest, fly])),
        quat=as_float32(quat),
        vel=as_float32(vel),
        angvel=as_float32(np.zeros((n, 3))),
        planes=as_float32(planes),
        plane_kind=kinds,
        materials=materials_array(c["materials"]),
        dt=float(c["dt"]),
        n_frames=n_frames,
        effects=Effects.from_dict(c.get("effects")),
    ).validate()
