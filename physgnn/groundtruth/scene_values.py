"""Checked values of a scene file (:mod:`physgnn.groundtruth.scenefile`): mappings of known
keys, numbers, vectors, directions, restitutions and materials, each wrong one a one-line
:class:`~physgnn.physics.scene.SceneError` naming its place (``where``); and a scene of arrays
(:func:`physgnn.api.scene_from_arrays`) checked by the same functions (:func:`arrays`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from physgnn.physics.scene import Material, Scene, SceneError, as_float32

MATERIAL_KEYS = tuple(f.name for f in dataclasses.fields(Material))


def known_keys(where: str, d, schema: dict) -> dict:
    """``d`` as a dict whose keys are all known to ``schema`` and whose required keys exist."""
    if not isinstance(d, dict):
        raise SceneError(f"{where}: expected a mapping, got {type(d).__name__}")
    known = schema["properties"]
    for key in d:
        if key not in known:
            raise SceneError(f"{where}: unknown key '{key}'; known: {', '.join(known)}")
    for key in schema.get("required", []):
        if key not in d:
            raise SceneError(f"{where}: missing key '{key}'")
    return d


def number(where: str, x, positive: bool = False) -> float:
    if isinstance(x, bool) or not isinstance(x, int | float) or not np.isfinite(x):
        raise SceneError(f"{where}: expected a number, got {x!r}")
    if positive and x <= 0:
        raise SceneError(f"{where}: must be > 0, got {x}")
    return float(x)


def vector(where: str, x, n: int) -> np.ndarray:
    if not isinstance(x, list | tuple) or len(x) != n:
        raise SceneError(f"{where}: expected a list of {n} numbers, got {x!r}")
    return np.array([number(where, v) for v in x], dtype=np.float64)


def unit(where: str, x, n: int) -> np.ndarray:
    v = vector(where, x, n)
    norm = float(np.linalg.norm(v))
    if norm < 1e-9:
        raise SceneError(f"{where}: has length 0 (needs a direction)")
    return v / norm


def restitution(where: str, x) -> float:
    """A restitution: a number in [0, 1]."""
    e = number(where, x)
    if not 0 <= e <= 1:
        raise SceneError(f"{where}: must be in [0, 1], got {e}")
    return e


def coefficients(where: str, values: dict) -> dict:
    """A material's coefficients (keys of :class:`Material`): numbers >= 0, the restitution
    at most 1."""
    checked = {k: number(f"{where}.{k}", v) for k, v in values.items()}
    for key, v in checked.items():
        if v < 0 or (key == "restitution" and v > 1):
            bound = "in [0, 1]" if key == "restitution" else ">= 0"
            raise SceneError(f"{where}.{key}: must be {bound}, got {v:g}")
    return checked


def arrays(where: str, scene: Scene) -> Scene:
    """``scene`` (made from arrays, not read from a file) once its values pass a scene file's
    checks: each material's coefficients (:func:`coefficients`), each orientation a direction
    (:func:`unit`; normalised, as a scene file's)."""
    for k, row in enumerate(np.asarray(scene.materials, np.float64).tolist()):
        coefficients(f"{where}: materials[{k}]", dict(zip(MATERIAL_KEYS, row, strict=True)))
    quat = [unit(f"{where}: quat[{i}]", q, 4) for i, q in enumerate(scene.quat.tolist())]
    return dataclasses.replace(scene, quat=as_float32(np.reshape(quat, (-1, 4))))
