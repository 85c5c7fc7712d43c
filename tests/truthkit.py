"""Ground-truth scenes shared by the engine, scene and simulate tests: spheres over the ground
(:func:`spheres`), bounce apexes (:func:`flight_apexes`), the scene configs of ``conf/scene``
(:func:`scene_cfg`, :func:`family`) and a tiny scene file's text (:data:`SCENE`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from physgnn import SCENES_DIR
from physgnn.physics.scene import Effects, Scene, ground_plane

G = 9.81
DT = 0.1  # s per frame


def spheres(
    pos,
    vel=None,
    angvel=None,
    quat=None,
    radius=0.5,
    material=(0.5, 0.5, 0.0, 0.0),
    n_frames=20,
    effects: Effects | None = None,
) -> Scene:
    """A scene of spheres (one material) over the ground; pos ``[N, 3]``."""
    pos = np.asarray(pos, dtype=np.float32).reshape(-1, 3)
    n = len(pos)
    zeros = np.zeros((n, 3), np.float32)
    q = np.tile([1.0, 0, 0, 0], (n, 1)) if quat is None else np.asarray(quat).reshape(n, 4)
    return Scene(
        name="test",
        radius=np.full(n, radius, np.float32),
        mass=np.ones(n, np.float32),
        material=np.zeros(n, np.int64),
        pos=pos,
        quat=q.astype(np.float32),
        vel=zeros if vel is None else np.asarray(vel, np.float32).reshape(n, 3),
        angvel=zeros if angvel is None else np.asarray(angvel, np.float32).reshape(n, 3),
        planes=ground_plane()[None],
        plane_kind=np.array([0]),
        materials=np.array([material], np.float32),
        dt=DT,
        n_frames=n_frames,
        effects=effects or Effects(),
    )


def flight_apexes(traj, r):
    """Apex height above the contact height of each flight after a bounce (engine states)."""
    z, vz = traj.pos[:, 0, 2] - r, traj.vel[:, 0, 2]
    apex = z + vz**2 / (2 * G)  # ballistic invariant: the apex of the current flight
    bounces = np.nonzero((vz[:-1] < 0) & (vz[1:] > 0))[0]
    return [apex[b + 2] for b in bounces]


def family(**overrides) -> dict:
    cfg = OmegaConf.to_container(OmegaConf.load(Path(SCENES_DIR) / "random_box.yaml"))
    return cfg | overrides


def scene_cfg(name: str, **overrides) -> dict:
    cfg = OmegaConf.to_container(OmegaConf.load(Path(SCENES_DIR) / f"{name}.yaml"))
    cfg.update(overrides)
    return cfg


SCENE = """
name: tiny
dt: 0.1
frames: 6
spheres:
  - {radius: 0.5, position: [0, 0, 2], velocity: [1, 0, 0]}
  - {radius: 0.5, position: [1.5, 0, 0.5]}
"""
