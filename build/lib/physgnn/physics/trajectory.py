"""The one container of a trajectory, whether the truth (the engine's frames) or a prediction
(a simulator's rollout): metrics, stability, reports and the training callback all take it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import torch

from physgnn.physics.kinematics import finite_difference_velocities
from physgnn.physics.scene import Effects

FRAME_KEYS = ("pos", "quat", "vel", "angvel")


@dataclass
class Trajectory:
    """A scene's static description plus its frames (what one HDF5 group holds).

    pos, vel, angvel ``[T, N, 3]``; quat ``[T, N, 4]`` (w, x, y, z); the rest as in
    :class:`~physgnn.physics.scene.Scene`. ``attrs`` holds the file attributes (dt, seed,
    config, …). The truth has the engine's velocities, ``start = 0`` and no ``fps``. A
    prediction has finite-difference velocities; frames ``0..start`` are the truth's seed
    frames (``start = H``), ``diverged_at`` is the first frame it could not compute (its
    arrays then hold the finite prefix, ``T = diverged_at``) and ``fps`` the frames it
    computed per second.
    """

    name: str
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    angvel: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    material: np.ndarray
    planes: np.ndarray
    plane_kind: np.ndarray
    materials: np.ndarray
    dt: float
    effects: Effects = field(default_factory=Effects)
    attrs: dict = field(default_factory=dict)
    start: int = 0
    diverged_at: int | None = None
    fps: float | None = None

    @property
    def n_frames(self) -> int:
        return int(self.pos.shape[0])

    @property
    def n_spheres(self) -> int:
        return int(self.pos.shape[1])

    def truncated(self, max_frames: int | None) -> Trajectory:
        """The first ``max_frames`` frames (all of them when None or 0)."""
        if not max_frames or self.n_frames <= max_frames:
            return self
        return dataclasses.replace(self, **{k: getattr(self, k)[:max_frames] for k in FRAME_KEYS})

    def with_finite_velocities(self) -> Trajectory:
        """The same frames with ``v_k = (p_k − p_{k−1})/dt`` (``v_0`` kept), what a rollout
        records. At dt = 0.1 s a bounce inside a frame interval makes this kinetic energy dip
        and recover, which the energy gain counts: the gain a perfect rollout would show."""
        f64 = lambda a: torch.as_tensor(np.asarray(a, np.float64))  # noqa: E731
        vel, _ = finite_difference_velocities(
            f64(self.pos), f64(self.quat), f64(self.vel[0]), f64(self.angvel[0]), self.dt
        )
        return dataclasses.replace(self, vel=vel.numpy())
