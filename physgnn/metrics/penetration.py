"""Penetration of spheres into each other, the ground and the other planes (definitions in
:mod:`physgnn.metrics`): the mean and percentage of :func:`penetration`, the maximum of
:func:`max_penetration`, from one pass over the intersections."""

from __future__ import annotations

import numpy as np
import torch

from physgnn.graph.neighbors import radius_pairs
from physgnn.metrics import checks
from physgnn.metrics.checks import MetricError, frames, per_sphere
from physgnn.physics.geometry import plane_depth, rectangle_distance
from physgnn.physics.scene import GROUND

PENETRATION_KEYS = (
    "depth_sphere",
    "depth_ground",
    "depth_static",
    "pct_sphere",
    "pct_ground",
    "pct_static",
)


def sphere_overlaps(pos_t: np.ndarray, radius: np.ndarray):
    """Overlapping pairs of one frame. pos_t ``[N, 3]`` → ``(i [P], j [P], depth [P])``, i < j,
    depth = ``r_i + r_j − |p_i − p_j| > 0`` (k-d tree candidates within ``2·r_max``)."""
    pairs = radius_pairs(torch.from_numpy(pos_t), 2.0 * radius.max(), backend="kdtree").numpy()
    i, j = pairs[0], pairs[1]
    depth = radius[i] + radius[j] - np.linalg.norm(pos_t[i] - pos_t[j], axis=-1)
    keep = depth > 0
    return i[keep], j[keep], depth[keep]


def _sphere_sphere(pos: np.ndarray, radius: np.ndarray):
    """Normalised depths of all intersections ``[K]`` and the deepest normalised depth of
    each sphere ``[N]`` (−inf without any pair)."""
    t_count, n = pos.shape[:2]
    deepest = np.full(n, -np.inf)
    if n < 2:
        return np.zeros(0), deepest
    if t_count * n * n <= checks.BRUTE_FORCE_MAX:
        iu, ju = np.triu_indices(n, k=1)
        sum_r = radius[iu] + radius[ju]
        norm_depth = (sum_r - np.linalg.norm(pos[:, iu] - pos[:, ju], axis=-1)) / sum_r  # [T, P]
        pair_max = norm_depth.max(0)
        np.maximum.at(deepest, iu, pair_max)
        np.maximum.at(deepest, ju, pair_max)
        return norm_depth[norm_depth > 0], deepest
    depths = []
    for pos_t in pos:  # one neighbour query per frame
        i, j, depth = sphere_overlaps(pos_t, radius)
        norm_depth = depth / (radius[i] + radius[j])
        np.maximum.at(deepest, i, norm_depth)
        np.maximum.at(deepest, j, norm_depth)
        depths.append(norm_depth)
    return np.concatenate(depths), deepest


def plane_distance(pos: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Distance from centres ``[..., 3]`` to the closest point of a bounded plane row ``[11]``
    (:func:`physgnn.physics.geometry.rectangle_distance`). → ``[...]``."""
    return rectangle_distance(torch.from_numpy(pos), torch.from_numpy(plane)).numpy()


def _sphere_planes(pos, radius, planes, kinds, ground: bool):
    """Normalised depths ``[K]`` and the deepest normalised depth of each sphere ``[N]``
    against the ground or against the other planes."""
    depths, deepest = [], np.full(pos.shape[1], -np.inf)
    for plane, kind in zip(planes, kinds, strict=True):
        if (kind == GROUND) != ground:
            continue
        depth = plane_depth(
            torch.from_numpy(pos), torch.from_numpy(radius), torch.from_numpy(plane), int(kind)
        ).numpy()
        norm_depth = depth / (2.0 * radius)  # [T, N]
        deepest = np.maximum(deepest, norm_depth.max(0))
        depths.append(norm_depth[norm_depth > 0])
    return (np.concatenate(depths) if depths else np.zeros(0)), deepest


def _intersections(pos, radius, planes, plane_kind) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per part (sphere, ground, static): all positive normalised depths and each sphere's
    deepest normalised depth (definitions in the module docstring)."""
    pos = frames(pos, "pos")
    radius = per_sphere(radius, pos.shape[1], "radius")
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 11)
    kinds = np.asarray(plane_kind).reshape(-1)
    if len(kinds) != len(planes):
        raise MetricError(f"{len(planes)} planes but {len(kinds)} plane kinds")
    return {
        "sphere": _sphere_sphere(pos, radius),
        "ground": _sphere_planes(pos, radius, planes, kinds, ground=True),
        "static": _sphere_planes(pos, radius, planes, kinds, ground=False),
    }


def penetration(pos, radius, planes, plane_kind, tol: float = 0.0) -> dict[str, float]:
    """Penetration metrics of a trajectory (definitions in the module docstring).

    pos ``[T, N, 3]``, radius ``[N]``, planes ``[S, 11]``, plane_kind ``[S]``; ``tol`` is a
    fraction of the diameter. Returns the floats of :data:`PENETRATION_KEYS` (pct in %).
    """
    out = {}
    for key, (depths, deepest) in _intersections(pos, radius, planes, plane_kind).items():
        out[f"depth_{key}"] = float(depths.mean()) if depths.size else 0.0
        out[f"pct_{key}"] = 100.0 * float((deepest > tol).mean())
    return {k: out[k] for k in PENETRATION_KEYS}


def max_penetration(pos, radius, planes, plane_kind) -> dict[str, float]:
    """Deepest intersection over all frames, as a fraction of the diameter:
    ``{max_pen_sphere, max_pen_ground, max_pen_static}`` (0 when nothing intersects), the mean
    sphere–sphere depth ``mean_pen_sphere`` (= ``depth_sphere`` of :func:`penetration`) and
    ``tunnelled``, the number of spheres whose centre crossed the ground or a plane."""
    parts = _intersections(pos, radius, planes, plane_kind)
    out = {f"max_pen_{key}": max(0.0, float(deepest.max())) for key, (_, deepest) in parts.items()}
    crossed = (parts["ground"][1] > 0.5) | (parts["static"][1] > 0.5)
    out["mean_pen_sphere"] = float(parts["sphere"][0].mean()) if parts["sphere"][0].size else 0.0
    out["tunnelled"] = int(crossed.sum())
    return out
