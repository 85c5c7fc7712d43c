"""Initial conditions of a scene (spheres, planes, materials, effects), shared by the generator,
the data files and the simulator. Pure numpy; knows nothing of pybullet or of the network.

Planes are rows of ``PLANE_DIM = 11`` numbers: centre ``p_s`` (3), unit normal ``n_s`` (3),
unit reference direction ``d_s`` (3, perpendicular to ``n_s``), and the **half** lengths
``L_x`` along ``d_s`` and ``L_y`` along ``n_s × d_s``. The ground is the plane ``z = 0`` with
infinite half lengths; it is always row 0 of a scene's planes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from physgnn.errors import PhysgnnError

PLANE_DIM = 11
PLANE_KINDS = ("ground", "wall", "static")
GROUND, WALL, STATIC = 0, 1, 2
GRAVITY = (0.0, 0.0, -9.81)
# The most frames of one scene: 1e4 s at dt 0.1 (a rollout of the report is 1 000 frames at
# most); more is a slip of the keyboard (1e9 frames: years of pybullet, and memory it lacks).
MAX_FRAMES = 100_000
EFFECT_NAMES = ("gravity", "sphere_contact", "surface_contact", "friction", "rotation")


class SceneError(PhysgnnError, ValueError):
    """Invalid scene or trajectory description (message is one line naming the problem)."""


@dataclass(frozen=True)
class Effects:
    """What a scene contains; the generator and the learned simulator compute only these."""

    gravity: bool = True
    sphere_contact: bool = True
    surface_contact: bool = True
    friction: bool = True
    rotation: bool = True

    def as_dict(self) -> dict[str, bool]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict | None) -> Effects:
        d = dict(d or {})
        unknown = set(d) - set(EFFECT_NAMES)
        if unknown:
            raise SceneError(f"unknown effect(s) {sorted(unknown)}; known: {list(EFFECT_NAMES)}")
        flags = {k: v.item() if isinstance(v, np.bool_) else v for k, v in d.items()}
        wrong = {k: v for k, v in flags.items() if not isinstance(v, bool)}
        if wrong:  # bool('no') is True: a word or a number is never taken for a switch
            key, value = next(iter(wrong.items()))
            raise SceneError(f"effect {key} must be true or false, got {value!r}")
        return cls(**flags)


@dataclass(frozen=True)
class Material:
    """Contact parameters of one material id (pybullet's names)."""

    restitution: float = 0.5
    lateral_friction: float = 0.5
    rolling_friction: float = 0.001
    spinning_friction: float = 0.001

    def as_array(self) -> np.ndarray:
        return np.array(dataclasses.astuple(self), dtype=np.float32)


# The coefficients of a plane that was given none (every scene and dataset before planes had
# materials): restitution 1, lateral friction 1, no rolling or spinning friction, so that the
# sphere's material alone sets a sphere–plane contact (Bullet multiplies restitutions and
# lateral frictions and adds rolling / spinning friction as r0·f1 + r1·f0).
PLANE_MATERIAL = (1.0, 1.0, 0.0, 0.0)


def as_float32(a) -> np.ndarray:
    """``a`` as a contiguous float32 array, the form of a :class:`Scene`'s arrays."""
    return np.ascontiguousarray(a, dtype=np.float32)


def default_plane_materials(n_planes: int) -> np.ndarray:
    """``[S, 4]`` float32: :data:`PLANE_MATERIAL` for each of ``n_planes`` planes."""
    return np.tile(np.asarray(PLANE_MATERIAL, dtype=np.float32), (int(n_planes), 1))


def make_plane(centre, normal, ref_dir, half_x: float, half_y: float) -> np.ndarray:
    """One plane row ``[11]``; normal and reference direction are normalised, checked ⟂."""
    n = np.asarray(normal, dtype=np.float64)
    d = np.asarray(ref_dir, dtype=np.float64)
    n, d = n / np.linalg.norm(n), d / np.linalg.norm(d)
    if abs(float(n @ d)) > 1e-6:
        raise SceneError(
            f"plane reference direction {d.tolist()} is not perpendicular to its normal"
        )
    row = np.concatenate([np.asarray(centre, dtype=np.float64), n, d, [half_x, half_y]])
    return row.astype(np.float32)


def ground_plane() -> np.ndarray:
    """The ground ``z = 0`` as a plane row ``[11]`` (infinite half lengths)."""
    return make_plane((0, 0, 0), (0, 0, 1), (1, 0, 0), np.inf, np.inf)


@dataclass
class Scene:
    """Initial conditions of one scene; arrays are float32 unless stated.

    radius, mass ``[N]``; material ``[N]`` int; pos ``[N, 3]``; quat ``[N, 4]`` (w, x, y, z);
    vel, angvel ``[N, 3]``; planes ``[S, 11]`` (row 0 the ground); plane_kind ``[S]`` int;
    materials ``[K, 4]`` (restitution, lateral, rolling, spinning friction); plane_materials
    ``[S, 4]`` the same coefficients per plane (None: :data:`PLANE_MATERIAL` for every plane).
    """

    name: str
    radius: np.ndarray
    mass: np.ndarray
    material: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    angvel: np.ndarray
    planes: np.ndarray
    plane_kind: np.ndarray
    materials: np.ndarray
    dt: float
    n_frames: int
    effects: Effects = field(default_factory=Effects)
    gravity: tuple[float, float, float] = GRAVITY
    plane_materials: np.ndarray | None = None

    @property
    def n_spheres(self) -> int:
        return int(self.radius.shape[0])

    def validate(self) -> Scene:
        """Raise :class:`SceneError` with one line naming the first problem found."""
        n = self.n_spheres
        if n < 1:
            raise SceneError(f"scene '{self.name}' has no sphere (a scene needs at least one)")
        shapes = {
            "mass": (n,),
            "material": (n,),
            "pos": (n, 3),
            "quat": (n, 4),
            "vel": (n, 3),
            "angvel": (n, 3),
        }
        for key, shape in shapes.items():
            if getattr(self, key).shape != shape:
                raise SceneError(
                    f"scene '{self.name}': {key} has shape "
                    f"{getattr(self, key).shape}, expected {shape}"
                )
        if not np.all(self.radius > 0):
            raise SceneError(
                f"scene '{self.name}': radius must be > 0 (got min {self.radius.min()})"
            )
        if not np.all(self.mass > 0):
            raise SceneError(f"scene '{self.name}': mass must be > 0 (got min {self.mass.min()})")
        if self.planes.ndim != 2 or self.planes.shape[1] != PLANE_DIM:
            raise SceneError(f"scene '{self.name}': planes must be [S, {PLANE_DIM}]")
        if self.plane_kind.shape != (self.planes.shape[0],):
            raise SceneError(f"scene '{self.name}': plane_kind must have one entry per plane")
        if self.dt <= 0 or self.n_frames < 2:
            raise SceneError(f"scene '{self.name}': need dt > 0 and n_frames >= 2")
        if self.n_frames > MAX_FRAMES:
            raise SceneError(
                f"scene '{self.name}': {self.n_frames} frames is more than {MAX_FRAMES} (a "
                "trajectory is kept whole in memory; 1e9 frames of pybullet would run for years):"
                f" simulate at most {MAX_FRAMES} frames, or a longer dt"
            )
        if self.material.min() < 0 or self.material.max() >= len(self.materials):
            raise SceneError(
                f"scene '{self.name}': material id out of range [0, {len(self.materials)})"
            )
        for key in ("radius", "mass", "pos", "quat", "vel", "angvel"):
            if not np.all(np.isfinite(getattr(self, key))):
                raise SceneError(f"scene '{self.name}': {key} contains NaN or inf")
        if self.plane_materials is not None:
            check_plane_materials(self.name, self.plane_materials, len(self.planes))
        check_float32_scale(self.name, self.pos, self.radius)
        check_speeds(self.name, self.pos, self.vel, self.radius, self.dt * (self.n_frames - 1))
        return self


def check_plane_materials(name: str, plane_materials: np.ndarray, n_planes: int) -> None:
    """Raise :class:`SceneError` unless ``plane_materials`` is ``[n_planes, 4]`` of finite
    coefficients >= 0 with restitution <= 1."""
    m = np.asarray(plane_materials)
    if m.shape != (n_planes, 4):
        raise SceneError(
            f"scene '{name}': plane_materials has shape {m.shape}, expected ({n_planes}, 4)"
        )
    if not np.all(np.isfinite(m)) or np.any(m < 0) or np.any(m[:, 0] > 1):
        raise SceneError(f"scene '{name}': plane_materials must be finite, >= 0, restitution <= 1")


# float32 (physgnn's tensors) resolves about 1.2e-7 of a value: the smallest sphere must span
# many such steps at the scene's extent, or contacts happen at the wrong place or not at all.
MIN_RADIUS_PER_EXTENT = 1e-5


def check_float32_scale(name: str, pos: np.ndarray, radius: np.ndarray) -> None:
    """Positions float32 can hold, and radii float32 resolves at the scene's extent (a scene
    at 1e30 m fell through the ground; a sphere of 1e-9 m bounced without touching)."""
    pos = np.asarray(pos, dtype=np.float32)
    if not np.all(np.isfinite(pos)):
        raise SceneError(f"scene '{name}': positions must be finite float32 numbers (< 3.4e38 m)")
    extent = max(1.0, float(np.abs(pos).max()))
    i = int(np.argmin(radius))
    if radius[i] < extent * MIN_RADIUS_PER_EXTENT:
        raise SceneError(
            f"scene '{name}': sphere {i} has radius {float(radius[i]):g} m in a scene reaching "
            f"{extent:g} m from the origin, finer than float32 resolves there: bring the scene "
            f"near the origin (metres), or give radii >= {extent * MIN_RADIUS_PER_EXTENT:g} m"
        )


def check_speeds(
    name: str, pos: np.ndarray, vel: np.ndarray, radius: np.ndarray, duration: float
) -> None:
    """Starting speeds whose straight flight over the scene's ``duration`` (s) stays where
    float32 resolves the smallest radius (:data:`MIN_RADIUS_PER_EXTENT`): pybullet froze a
    sphere thrown at 1e30 m/s (it did not even fall) instead of failing."""
    speed = np.linalg.norm(np.asarray(vel, np.float64), axis=1)
    start = float(np.abs(np.asarray(pos, np.float64)).max())
    limit = max(1.0, float(radius.min()) / MIN_RADIUS_PER_EXTENT) - start
    i = int(np.argmax(speed))
    if speed[i] * duration > limit:
        raise SceneError(
            f"scene '{name}': sphere {i} starts at {speed[i]:g} m/s, which carries it farther "
            f"in the scene's {duration:g} s than float32 resolves a radius of "
            f"{float(radius.min()):g} m: give speeds below {max(limit, 0) / duration:g} m/s"
        )
