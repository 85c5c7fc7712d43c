"""Building blocks of scenes: materials, planes (ground, arena walls, ramps) and sphere layouts
(spawned without overlap, clustered, cubes, piles), all numpy; the checks of a layout (spheres
clear of planes and of each other, the latter by a scipy k-d tree)."""

from __future__ import annotations

from collections.abc import Mapping
from itertools import chain

import numpy as np
from scipy.spatial import cKDTree

from physgnn.physics.scene import (
    GROUND,
    WALL,
    Material,
    SceneError,
    ground_plane,
    make_plane,
)

OVERLAP_TOL = 1e-9  # m: spheres deeper into each other than this overlap
_CHUNK = 256  # spheres searched at once (memory stays linear in N even if all overlap)


def materials_array(materials: list[Mapping]) -> np.ndarray:
    """``[K, 4]`` (restitution, lateral, rolling, spinning friction) from a list of dicts."""
    if not materials:
        raise SceneError("scene config needs at least one material")
    rows = [Material(**dict(m)).as_array() for m in materials]
    arr = np.stack(rows)
    if np.any(arr < 0) or np.any(arr[:, 0] > 1):
        raise SceneError("material coefficients must be >= 0 and restitution <= 1")
    return arr


def random_quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniformly random unit quaternions ``[n, 4]`` (w, x, y, z) with w ≥ 0."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, :1] < 0, -q, q)


def arena_planes(side: float, wall_height: float) -> tuple[np.ndarray, np.ndarray]:
    """Ground + 4 inward-facing walls around ``[-side/2, side/2]²``: planes ``[5, 11]``,
    kinds ``[5]``."""
    h = side / 2
    rows, kinds = [ground_plane()], [GROUND]
    for normal, ref in (
        ((-1, 0, 0), (0, 1, 0)),
        ((1, 0, 0), (0, -1, 0)),
        ((0, -1, 0), (-1, 0, 0)),
        ((0, 1, 0), (1, 0, 0)),
    ):
        centre = -h * np.asarray(normal, dtype=np.float64) + [0, 0, wall_height / 2]
        rows.append(make_plane(centre, normal, ref, h, wall_height / 2))
        kinds.append(WALL)
    return np.stack(rows), np.asarray(kinds, dtype=np.int64)


def ground_only() -> tuple[np.ndarray, np.ndarray]:
    return ground_plane()[None], np.asarray([GROUND], dtype=np.int64)


def ramp_plane(centre, slope_deg: float, half_length: float, half_width: float) -> np.ndarray:
    """A bounded plane tilted by ``slope_deg`` about the y axis, descending towards +x."""
    a = np.deg2rad(slope_deg)
    normal = (np.sin(a), 0.0, np.cos(a))
    downhill = (np.cos(a), 0.0, -np.sin(a))
    return make_plane(centre, normal, downhill, half_length, half_width)


def spawn_without_overlap(
    rng, radius: np.ndarray, low: np.ndarray, high: np.ndarray, tries: int
) -> np.ndarray:
    """Reject-sample centres ``[N, 3]`` with centre ∈ [low + r, high − r] (per axis; the z
    range is [low_z + r, high_z]) and no two spheres overlapping. Raises SceneError after
    ``tries`` failed draws for one sphere."""
    pos = np.empty((len(radius), 3))
    for i, r in enumerate(radius):
        lo = low + r
        hi = np.array([high[0] - r, high[1] - r, high[2]])
        if np.any(hi < lo):
            raise SceneError(f"sphere of radius {r:.3g} does not fit in the spawn volume")
        for _ in range(tries):
            x = rng.uniform(lo, hi)
            gap = np.linalg.norm(pos[:i] - x, axis=1) - radius[:i] - r
            if np.all(gap > 0):
                pos[i] = x
                break
        else:
            raise SceneError(
                f"could not place sphere {i + 1} of {len(radius)} without overlap "
                f"in {tries} tries (use a larger arena, more height or fewer spheres)"
            )
    return pos


def clustered_positions(
    rng, radius: np.ndarray, half: float, h_max: float, max_gap: float
) -> np.ndarray | None:
    """Centres ``[N, 3]`` on a random subset of a cubic lattice whose spheres are
    U[0.01, max_gap] m apart (surface to surface for the largest radius): a block of close,
    non-touching spheres anywhere in the spawn volume. None when the block does not fit."""
    n, r_max = len(radius), float(radius.max())
    k = int(np.ceil(n ** (1 / 3) - 1e-9))
    step = 2 * r_max + rng.uniform(0.01, max_gap)
    span = (k - 1) * step
    if span > 2 * (half - r_max) or r_max + span > h_max:
        return None
    cells = np.stack(np.meshgrid(*[np.arange(k)] * 3, indexing="ij"), -1).reshape(-1, 3)
    cells = cells[rng.permutation(len(cells))[:n]]
    low = np.array([-half + r_max, -half + r_max, r_max])
    high = np.array([half - r_max - span, half - r_max - span, h_max - span])
    return rng.uniform(low, high) + step * cells


def cube_positions(corner, k: int, radius: float, gap: float) -> np.ndarray:
    """Centres ``[k³, 3]`` of a k×k×k cube of spheres, bottom-front-left centre at
    ``corner``, neighbours ``gap`` apart (surface to surface)."""
    step = 2 * radius + gap
    idx = np.stack(np.meshgrid(*[np.arange(k)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return np.asarray(corner, dtype=np.float64) + step * idx


def check_clear_of_planes(
    name: str, pos: np.ndarray, radius, planes: np.ndarray, depth: float = 1.0
) -> None:
    """Raise SceneError if a sphere starts on or inside a bounded plane (or the ``depth`` m
    of solid behind it, as the engine builds it)."""
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(pos),))
    for row in planes[1:]:
        centre, n, d = row[:3], row[3:6], row[6:9]
        rel = pos - centre
        along, across, normal = rel @ d, rel @ np.cross(n, d), rel @ n
        inside = (np.abs(along) <= row[9] + radius) & (np.abs(across) <= row[10] + radius)
        hit = inside & (normal > -depth - radius) & (normal < radius)
        if np.any(hit):
            i = int(np.argmax(hit))
            raise SceneError(
                f"scene '{name}': sphere {i} at {np.round(pos[i], 2).tolist()} "
                "starts on or inside a plane; move it"
            )


def check_above_ground(where: str, pos: np.ndarray, radius: np.ndarray) -> None:
    """Raise SceneError naming the first sphere that reaches below the ground z = 0."""
    below = pos[:, 2] - radius < -1e-9
    if np.any(below):
        i = int(np.argmax(below))
        raise SceneError(f"{where}: spheres[{i}] reaches below the ground z = 0 (z - r < 0)")


def check_no_overlap(where: str, pos: np.ndarray, radius: np.ndarray) -> None:
    """Raise SceneError naming the first two overlapping spheres (pos ``[N, 3]``, radius
    ``[N]``): a neighbour search, memory linear in N (no ``[N, N]`` distances)."""
    classes = _size_classes(pos, radius)
    for start in range(0, len(pos), _CHUNK):
        i, j = _candidates(classes, pos, radius, np.arange(start, min(start + _CHUNK, len(pos))))
        gap = np.linalg.norm(pos[i] - pos[j], axis=1) - radius[i] - radius[j]
        hit = np.flatnonzero(gap < -OVERLAP_TOL)
        if hit.size:
            k = hit[np.lexsort((j[hit], i[hit]))[0]]
            raise SceneError(
                f"{where}: spheres[{i[k]}] and spheres[{j[k]}] overlap by {-gap[k]:.3g} m"
            )


def _size_classes(pos: np.ndarray, radius: np.ndarray) -> list[tuple[cKDTree, np.ndarray, float]]:
    """One k-d tree per size class (radii within a factor of 2): ``(tree, members [M], largest
    radius)``. Searching each class out to its own largest radius keeps a big sphere among
    small ones from making every small pair a candidate."""
    size = np.floor(np.log2(radius)).astype(np.int64)
    classes = []
    for c in np.unique(size):
        members = np.flatnonzero(size == c)
        classes.append((cKDTree(pos[members]), members, float(radius[members].max())))
    return classes


def _candidates(classes, pos, radius, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i [P], j [P])``, ``i`` in ``rows`` and ``j > i``, of spheres that may overlap:
    ``j`` within ``r_i`` + the largest radius of ``j``'s class (every overlapping pair of
    ``rows`` with a later sphere is among them)."""
    i_all, j_all = [], []
    for tree, members, r_max in classes:
        hits = tree.query_ball_point(pos[rows], radius[rows] + r_max)
        counts = np.fromiter(map(len, hits), dtype=np.int64, count=len(rows))
        flat = np.fromiter(chain.from_iterable(hits), dtype=np.int64, count=int(counts.sum()))
        i, j = np.repeat(rows, counts), members[flat]
        i_all.append(i[j > i])
        j_all.append(j[j > i])
    return np.concatenate(i_all), np.concatenate(j_all)


def pile_positions(n: int, layers: int, radius: float) -> np.ndarray:
    """Centres ``[K, 3]`` of a square pyramid of touching spheres resting on the ground: layer
    ``l`` is ``(n − l)²`` spheres ``2r`` apart, in the hollows of the layer below (shifted by
    ``(r, r)``, raised by ``√2·r``); the bottom layer touches the ground. ``layers = 1``: a flat
    n×n layer."""
    pos = []
    for layer in range(layers):
        k = n - layer
        xy = (np.arange(k) - (k - 1) / 2) * 2 * radius
        gx, gy = np.meshgrid(xy, xy, indexing="ij")
        z = radius + layer * np.sqrt(2.0) * radius
        pos.append(np.stack([gx.ravel(), gy.ravel(), np.full(k * k, z)], axis=1))
    return np.concatenate(pos)


def contact_gap(rng, max_gap: float) -> float:
    """A surface gap of a dense layout: exactly touching half the time, else U(0, max_gap)."""
    return 0.0 if rng.uniform() < 0.5 else float(rng.uniform(0.0, max_gap))


def aggregate_positions(rng, radius: np.ndarray, max_gap: float, tries: int = 200) -> np.ndarray:
    """Centres ``[N, 3]`` of a random aggregate, lowest point at z = 0: each sphere after the
    first touches (or nearly touches, :func:`contact_gap`) a random earlier one from a random
    direction without overlapping any; so every sphere has 1–12 neighbours at random gaps, in
    no lattice. Raises SceneError when a sphere finds no place in ``tries`` draws."""
    pos = np.zeros((len(radius), 3))
    for i in range(1, len(radius)):
        for _ in range(tries):
            k = int(rng.integers(i))
            u = rng.normal(size=3)
            u /= np.linalg.norm(u)
            x = pos[k] + (radius[k] + radius[i] + contact_gap(rng, max_gap)) * u
            if np.all(np.linalg.norm(pos[:i] - x, axis=1) - radius[:i] - radius[i] > -OVERLAP_TOL):
                pos[i] = x
                break
        else:
            raise SceneError(f"aggregate: no place for sphere {i + 1} in {tries} tries")
    pos[:, 2] -= (pos[:, 2] - radius).min()
    return pos


def row_positions(rng, radius: np.ndarray, max_gap: float) -> np.ndarray:
    """Centres ``[N, 3]`` of a straight row on the ground (z = r) along a random horizontal
    direction, centred at 0, neighbours' centres ``r_i + r_j + g`` apart horizontally
    (:func:`contact_gap`): touching or nearly touching when of one radius, a few centimetres
    more apart when their radii differ (their centres are at different heights)."""
    step = [radius[i] + radius[i + 1] + contact_gap(rng, max_gap) for i in range(len(radius) - 1)]
    along = np.concatenate([[0.0], np.cumsum(step)])
    along -= along.mean()
    a = rng.uniform(0, 2 * np.pi)
    return np.stack([along * np.cos(a), along * np.sin(a), radius], axis=1)
