"""Checked values of a scene file (:mod:`physgnn.groundtruth.scenefile`): mappings of known
keys, numbers, vectors, directions and restitutions, each wrong one a one-line
:class:`~physgnn.physics.scene.SceneError` naming its place (``where``)."""

from __future__ import annotations

import numpy as np

from physgnn.physics.scene import SceneError


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
