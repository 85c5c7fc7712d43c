"""The one container of a trajectory, whether the truth (the engine's frames) or a prediction
(a simulator's rollout): metrics, stability, reports and the training callback all take it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import torch

from physgnn.physics.kinematics import finite_difference_velocities
from physgnn.physics.scene import (
    GRAVITY,
    GROUND,
    Effects,
    Material,
    Scene,
    SceneError,
    default_plane_materials,
    ground_plane,
)

FRAME_KEYS = ("pos", "quat", "vel", "angvel")
# Mass of an imported sphere given none: water's density (kg/m³) times its volume.
DEFAULT_DENSITY = 1000.0


@dataclass
class Trajectory:
    """A scene's static description plus its frames (what one HDF5 group holds).

    pos, vel, angvel ``[T, N, 3]``; quat ``[T, N, 4]`` (w, x, y, z); the rest as in
    :class:`~physgnn.physics.scene.Scene`. ``attrs`` holds the file attributes (dt, seed,
    config, …). The truth has the engine's velocities, ``start = 0`` and no ``fps``. A
    prediction has finite-difference velocities; frames ``0..start`` are the truth's seed
    frames (``start = H``), ``diverged_at`` is the first frame it could not compute (its
    arrays then hold the finite prefix, ``T = diverged_at``) and ``fps`` the frames it
    computed per second. ``plane_materials [S, 4]``: each plane's coefficients (restitution,
    lateral, rolling, spinning friction); None (data written before planes had materials):
    :data:`~physgnn.physics.scene.PLANE_MATERIAL` each, what the engine then gave every plane.
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
    plane_materials: np.ndarray | None = None

    @property
    def plane_coefficients(self) -> np.ndarray:
        """``[S, 4]`` float32: ``plane_materials``, or the default of every plane when None."""
        if self.plane_materials is None:
            return default_plane_materials(len(self.planes))
        return np.asarray(self.plane_materials, dtype=np.float32)

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
        """The same frames with ``v_k = (p_k − p_{k−1})/dt`` (``v_0`` kept), what a
        finite-difference rollout records and every simulator's energy is measured from in
        ``make eval``. At dt = 0.1 s a bounce inside a frame interval makes this kinetic energy dip
        and recover, which the energy gain counts: the gain a perfect rollout would show."""
        vel, _ = finite_difference_velocities(
            _float64(self.pos),
            _float64(self.quat),
            _float64(self.vel[0]),
            _float64(self.angvel[0]),
            self.dt,
        )
        return dataclasses.replace(self, vel=vel.numpy())

    @classmethod
    def from_arrays(
        cls,
        pos,
        radius,
        dt: float,
        *,
        quat=None,
        velocities=None,
        mass=None,
        materials=None,
        planes=None,
        effects: Effects | None = None,
        name: str | tuple[str, dict] = "imported",
    ) -> Trajectory:
        """A trajectory from plain arrays (another engine's spheres, a DEM code's output).

        pos ``[T, N, 3]`` and radius ``[N]`` (or one number) are needed; the rest defaults to:
        quat ``[T, N, 4]`` (w, x, y, z) the identity; velocities ``(vel, angvel)``, each
        ``[T, N, 3]``, by finite differences of pos and quat (frame 0 takes frame 1's, or zero
        for one frame); mass ``[N]`` from :data:`DEFAULT_DENSITY`; materials ``(table [K, 4],
        index [N])`` one default :class:`~physgnn.physics.scene.Material` that every sphere
        takes; planes ``(rows [S, 11], kinds [S])`` the ground alone; name ``(name, attrs)``
        ``"imported"`` without attributes. Where a pair is asked for, a tuple of two gives
        both, and one value (not a tuple) the first, the second taking its default (planes
        need both). A wrong shape, a dt or radius not > 0, or a value not finite (NaN, inf)
        raises a one-line ``SceneError``.
        """
        pos = _finite("pos", _array("pos", pos, np.float32, (None, None, 3)))
        t, n = pos.shape[:2]
        dt = _positive("dt", dt, "seconds between frames")
        radius = np.asarray(_positive("radius", radius, "metres"), np.float32)
        radius = _array("radius", radius if radius.ndim else np.full(n, radius), np.float32, (n,))
        quat = _frames("quat", quat, (t, n, 4), _identity(t, n))
        vel, angvel = _pair(velocities)
        vel_fd, angvel_fd = _finite_velocities(pos, quat, dt)
        name, attrs = _pair(name)
        return cls(
            name=name,
            pos=pos,
            quat=quat,
            dt=float(dt),
            effects=_effects(effects),
            vel=_frames("vel", vel, (t, n, 3), vel_fd),
            attrs=dict(attrs or {}),
            angvel=_frames("angvel", angvel, (t, n, 3), angvel_fd),
            **_static_fields(radius, mass, materials, planes),
        )


STATIC_KEYS = ("radius", "mass", "material", "planes", "plane_kind", "materials", "plane_materials")


def scene_at(traj: Trajectory, t: int) -> Scene:
    """The scene of ``traj`` from its frame ``t`` (positions, orientations, velocities) to its
    last frame (``T - t`` frames), at its gravity."""
    return Scene(
        name=traj.name,
        n_frames=traj.n_frames - t,
        dt=traj.dt,
        effects=traj.effects,
        gravity=tuple(traj.attrs.get("gravity", GRAVITY)),
        **{k: getattr(traj, k)[t] for k in FRAME_KEYS},
        **{k: getattr(traj, k) for k in STATIC_KEYS},
    )


def continued(truth: Trajectory, run: Trajectory, start: int, fps: float) -> Trajectory:
    """``truth``'s frames ``0..start``, then ``run`` (an engine run of :func:`scene_at` of
    ``truth`` at ``start``) from its frame 1 on, with finite-difference velocities: a
    prediction recorded as a rollout is (``start``, ``fps``)."""
    frames = {
        k: np.concatenate([getattr(truth, k)[: start + 1], getattr(run, k)[1:]]) for k in FRAME_KEYS
    }
    pred = dataclasses.replace(truth, **frames, attrs=dict(truth.attrs), start=start, fps=fps)
    return pred.with_finite_velocities()


def _static_fields(radius: np.ndarray, mass, materials, planes) -> dict:
    """The arrays of :meth:`Trajectory.from_arrays` that do not change over frames, checked,
    with their defaults (``radius`` ``[N]``, already checked)."""
    n = len(radius)
    volume = 4 / 3 * np.pi * radius.astype(np.float64) ** 3
    table, index = _pair(materials)
    if planes is not None and not _is_pair(planes):
        raise SceneError(
            "Trajectory.from_arrays: planes must be a pair (rows [S, 11], kinds [S]), "
            "e.g. planes=(planes, plane_kind)"
        )
    rows, kinds = planes if planes is not None else (None, None)
    return {
        "radius": radius,
        "mass": _frames("mass", mass, (n,), DEFAULT_DENSITY * volume),
        "material": _frames("material", index, (n,), np.zeros(n), np.int64),
        "materials": _frames("materials", table, (None, 4), Material().as_array()[None]),
        "planes": _frames("planes", rows, (None, 11), ground_plane()[None]),
        "plane_kind": _frames("plane_kind", kinds, (None,), [GROUND], np.int64),
    }


def _effects(value) -> Effects:
    """``value`` (None: every effect on, an :class:`Effects`, or a dict of switches) as an
    :class:`Effects`; else a one-line ``SceneError``."""
    if value is None or isinstance(value, Effects):
        return value or Effects()
    if not isinstance(value, dict):
        raise SceneError(
            "Trajectory.from_arrays: effects must be an Effects or a dict of switches, e.g. "
            f"{{'gravity': False}}, got {type(value).__name__}"
        )
    try:
        return Effects.from_dict(value)
    except SceneError as e:
        raise SceneError(f"Trajectory.from_arrays: effects: {e}") from None


def _is_pair(value) -> bool:
    return isinstance(value, tuple) and len(value) == 2


def _pair(value) -> tuple:
    """``value`` as ``(first, second)``: a tuple of two as it is, else ``(value, None)``."""
    return value if _is_pair(value) else (value, None)


def _array(key: str, value, dtype, shape: tuple) -> np.ndarray:
    """``value`` as a ``dtype`` array of ``shape`` (None: any size); else a ``SceneError``."""
    want = "[" + ", ".join("*" if s is None else str(s) for s in shape) + "]"
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError):  # "abc", a ragged list, an object
        shown = repr(value) if len(repr(value)) <= 40 else f"a {type(value).__name__}"
        raise SceneError(
            f"Trajectory.from_arrays: {key} must be an array of numbers {want}, got {shown}"
        ) from None
    fits = arr.ndim == len(shape) and all(
        s in (None, a) for s, a in zip(shape, arr.shape, strict=True)
    )
    if not fits:
        raise SceneError(
            f"Trajectory.from_arrays: {key} has shape {list(arr.shape)}, expected {want}"
        )
    return arr


def _frames(key: str, value, shape: tuple, default, dtype=np.float32) -> np.ndarray:
    """:func:`_array` of ``value``, or of ``default`` when ``value`` is None; finite (planes:
    not NaN, an infinite half length is an unbounded plane)."""
    arr = _array(key, default if value is None else value, dtype, shape)
    _finite(key, np.where(np.isposinf(arr), 0, arr) if key == "planes" else arr)
    return arr


def _finite(key: str, arr: np.ndarray) -> np.ndarray:
    """``arr``, once every value is finite; else a ``SceneError`` naming the first bad one."""
    bad = np.argwhere(~np.isfinite(arr)) if arr.dtype.kind == "f" else ()
    if len(bad):
        index = bad[0].tolist()
        where = f"frame {index[0]}, sphere {index[1]}" if arr.ndim >= 3 else f"index {index}"
        raise SceneError(
            f"Trajectory.from_arrays: {key} holds {arr[tuple(index)]} at {where} "
            f"({len(bad)} values not finite): give finite numbers"
        )
    return arr


def _positive(key: str, value, unit: str):
    """``value`` (a number, or an array ``[N]``) once each is finite and > 0; else a
    ``SceneError`` naming the first that is not."""
    try:
        arr = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        arr = np.array(np.nan)
    good = np.isfinite(arr) & (arr > 0)
    if not good.all():
        first = int(np.flatnonzero(~good)[0])
        got = value if arr.ndim == 0 else f"{arr.flat[first]:g} (sphere {first})"
        raise SceneError(
            f"Trajectory.from_arrays: {key} must be a number > 0 ({unit}), got {got!s}"
        )
    return float(arr) if arr.ndim == 0 else np.asarray(value)


def _identity(t: int, n: int) -> np.ndarray:
    quat = np.zeros((t, n, 4), np.float32)
    quat[..., 0] = 1.0
    return quat


def _float64(a) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, np.float64))


def _finite_velocities(pos: np.ndarray, quat: np.ndarray, dt: float):
    """vel, angvel ``[T, N, 3]`` by finite differences, frame 0 a copy of frame 1."""
    zeros = torch.zeros(pos.shape[1:], dtype=torch.float64)
    vel, angvel = finite_difference_velocities(_float64(pos), _float64(quat), zeros, zeros, dt)
    if pos.shape[0] > 1:
        vel[0], angvel[0] = vel[1], angvel[1]
    return vel.float().numpy(), angvel.float().numpy()
