"""The common tail of every scene family: the scene's materials (fixed or drawn), its planes'
materials, masses and orientations, into a validated :class:`~physgnn.physics.scene.Scene`."""

from __future__ import annotations

import dataclasses

import numpy as np
from omegaconf import DictConfig, OmegaConf

from physgnn.groundtruth.layouts import materials_array, random_quaternions
from physgnn.physics.scene import (
    PLANE_MATERIAL,
    Effects,
    Material,
    Scene,
    SceneError,
    as_float32,
)

MATERIAL_KEYS = tuple(f.name for f in dataclasses.fields(Material))


def plain_config(cfg) -> dict:
    """A config (DictConfig, mapping or None) as a plain, resolved dict."""
    if isinstance(cfg, DictConfig):
        return OmegaConf.to_container(cfg, resolve=True)
    return dict(cfg or {})


def _range(where: str, value) -> tuple[float, float]:
    """``[low, high]`` of a config as two floats with 0 <= low <= high."""
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise SceneError(f"{where}: expected [low, high], got {value!r}") from None
    if not 0 <= low <= high:
        raise SceneError(f"{where}: need 0 <= low <= high (got [{low}, {high}])")
    return low, high


def draw_materials(c: dict, rng: np.random.Generator) -> np.ndarray:
    """``[K, 4]`` materials of a scene: with ``material_ranges`` (a ``[low, high]`` per
    coefficient of :class:`~physgnn.physics.scene.Material`), ``materials_per_scene`` rows whose
    every coefficient is uniform in its range, drawn independently of the others (restitution
    says nothing of friction); without, the fixed rows of ``materials``."""
    ranges = c.get("material_ranges")
    if not ranges:
        return materials_array(c["materials"])
    if set(ranges) != set(MATERIAL_KEYS):
        raise SceneError(
            f"scene '{c['name']}': material_ranges needs exactly the keys {list(MATERIAL_KEYS)} "
            f"(got {sorted(ranges)})"
        )
    bounds = np.array([_range(f"material_ranges.{k}", ranges[k]) for k in MATERIAL_KEYS])
    if bounds[0, 1] > 1:
        raise SceneError(f"scene '{c['name']}': material_ranges.restitution must stay <= 1")
    k = int(c["materials_per_scene"])
    if k < 1:
        raise SceneError(f"scene '{c['name']}': materials_per_scene must be >= 1 (got {k})")
    return rng.uniform(bounds[:, 0], bounds[:, 1], size=(k, len(MATERIAL_KEYS)))


def draw_plane_materials(c: dict, rng: np.random.Generator, n_planes: int) -> np.ndarray | None:
    """``[S, 4]`` plane materials of a scene: with ``plane_restitution`` = ``[low, high]``, one
    restitution uniform in it for all the scene's planes, their friction that of
    :data:`~physgnn.physics.scene.PLANE_MATERIAL` (the sphere's friction alone counts); None
    (every plane :data:`~physgnn.physics.scene.PLANE_MATERIAL`) without."""
    if c.get("plane_restitution") is None:
        return None
    low, high = _range(f"scene '{c['name']}': plane_restitution", c["plane_restitution"])
    if high > 1:
        raise SceneError(f"scene '{c['name']}': plane_restitution must stay <= 1")
    row = np.array([rng.uniform(low, high), *PLANE_MATERIAL[1:]], dtype=np.float32)
    return np.tile(row, (n_planes, 1))


def finish_scene(
    c: dict, pos, radius, rng, planes, kinds, vel=None, angvel=None, material=None
) -> Scene:
    """Masses (``density``), orientations, materials (:func:`draw_materials`, one per sphere at
    random unless ``material`` is given), plane materials and effects; validates the scene."""
    pos = np.asarray(pos, dtype=np.float64).reshape(-1, 3)
    n = len(pos)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
    if np.any(radius <= 0):
        raise SceneError(f"scene '{c['name']}': radius must be > 0 (got {radius.min()})")
    mats = draw_materials(c, rng)
    if material is None:
        material = rng.integers(0, len(mats), size=n)
    zeros = np.zeros((n, 3))
    scene = Scene(
        name=c["name"],
        radius=as_float32(radius),
        mass=as_float32(c["density"] * 4 / 3 * np.pi * radius**3),
        material=np.asarray(material, dtype=np.int64),
        pos=as_float32(pos),
        quat=as_float32(random_quaternions(rng, n)),
        vel=as_float32(zeros if vel is None else vel),
        angvel=as_float32(zeros if angvel is None else angvel),
        planes=as_float32(planes),
        plane_kind=np.asarray(kinds, dtype=np.int64),
        materials=as_float32(mats),
        dt=float(c["dt"]),
        n_frames=int(c["n_frames"]),
        effects=Effects.from_dict(c.get("effects")),
        plane_materials=draw_plane_materials(c, rng, len(planes)),
    )
    return scene.validate()
