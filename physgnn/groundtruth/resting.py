"""Layouts of spheres resting on spheres, numpy only: vertical columns, square pyramids,
hexagonal close-packed layers and random stable deposits, each on the ground at z = 0 and
centred at the origin, neighbours touching or a small gap apart (:func:`contact_gap`).

Their support angles (the contact normal's angle from vertical): 0° in a column, 45° in a
square pyramid and 35.3° between hexagonal layers (at gaps 0; gaps move them a few degrees),
and a spread from about 15° to 60° in a deposit of mixed radii (a sphere in the hollow of
three unequal ones). None of them is a simple cubic block (``conf/scene/tight_pack.yaml``), the
lattice left out of training: columns never touch each other, and no layout has a sphere with
three mutually perpendicular bonds.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from physgnn.groundtruth.layouts import OVERLAP_TOL, contact_gap
from physgnn.physics.scene import SceneError

REST_KINDS = ("column", "pyramid", "hex_layers", "deposit")
COLUMN_CLEARANCE = 0.1  # m: least surface gap between two columns (they never touch)
# Layers of a pyramid or of hexagonal layers. Measured in pybullet (drawn materials, no nudge):
# with three, the bottom spheres roll out (2 of 2 of each collapsed, as resting_pile.yaml says
# of its pyramid); with two, 3 of 4 pyramids held and 0 of 4 hexagonal patches did.
LATTICE_LAYERS = 2
TRIES = 1000  # random places tried for a column or a ground sphere before giving up
INSIDE_MARGIN = 0.05  # least barycentric weight of a deposited sphere over its three supports


def _clear(pos: np.ndarray, radius: np.ndarray, x: np.ndarray, r: float) -> bool:
    """True when a sphere ``(x, r)`` overlaps none of ``pos [M, 3]``, ``radius [M]``."""
    gaps = np.linalg.norm(pos - x, axis=1) - radius - r
    return bool(np.all(gaps > -OVERLAP_TOL))


def column_positions(rng, n: int, r_min: float, r_max: float, max_gap: float):
    """``(pos [n, 3], radius [n])``: 1 to ⌊n/2⌋ vertical columns of 2 or more spheres of radii
    U[r_min, r_max], each sphere straight above the one below (gap :func:`contact_gap`), the
    columns' axes apart by their largest radii plus U[0.1, 1] m."""
    n_cols = int(rng.integers(1, max(1, n // 2) + 1))
    sizes = np.full(n_cols, n // n_cols)
    sizes[: n % n_cols] += 1
    radius = rng.uniform(r_min, r_max, size=n)
    pos, start, axes, widths = np.zeros((n, 3)), 0, [], []
    for size in sizes:
        r = radius[start : start + size]
        z = np.cumsum(
            np.r_[r[0], [r[k] + r[k + 1] + contact_gap(rng, max_gap) for k in range(size - 1)]]
        )
        width = float(r.max())
        x = _column_axis(rng, axes, widths, width)
        pos[start : start + size] = np.c_[np.tile(x, (size, 1)), z]
        axes.append(x)
        widths.append(width)
        start += size
    pos[:, :2] -= pos[:, :2].mean(0)
    return pos, radius


def _column_axis(rng, axes: list, widths: list, width: float) -> np.ndarray:
    """A column's axis ``[2]`` beside a random earlier one, clear of every earlier column."""
    if not axes:
        return np.zeros(2)
    for _ in range(TRIES):
        k = int(rng.integers(len(axes)))
        a = rng.uniform(0, 2 * np.pi)
        d = widths[k] + width + rng.uniform(COLUMN_CLEARANCE, 1.0)
        x = axes[k] + d * np.array([np.cos(a), np.sin(a)])
        apart = np.linalg.norm(np.asarray(axes) - x, axis=1) - np.asarray(widths) - width
        if np.all(apart >= COLUMN_CLEARANCE):
            return x
    raise SceneError(f"rest layout: no place for column {len(axes) + 1} in {TRIES} tries")


def pyramid_positions(rng, n: int, radius: float, max_gap: float) -> np.ndarray:
    """``[K, 3]``, K <= n: a square pyramid of spheres of one radius, base k×k with k drawn
    among those that leave room for two layers in n (k = 1 below 5 spheres), and the second
    layer in its hollows (:data:`LATTICE_LAYERS`); in-layer and between-layer surface gaps
    :func:`contact_gap` (one each)."""
    fits = [m for m in range(2, n + 1) if m * m + (m - 1) ** 2 <= n] or [1]
    k = int(rng.choice(fits))
    step = 2 * radius + contact_gap(rng, max_gap)
    rise = np.sqrt((2 * radius + contact_gap(rng, max_gap)) ** 2 - step**2 / 2)
    layers, used = [], 0
    for layer in range(min(k, LATTICE_LAYERS)):
        m = k - layer
        if used + m * m > n:
            break
        xy = (np.arange(m) - (m - 1) / 2) * step
        gx, gy = np.meshgrid(xy, xy, indexing="ij")
        z = radius + layer * rise
        layers.append(np.stack([gx.ravel(), gy.ravel(), np.full(m * m, z)], axis=1))
        used += m * m
    return np.concatenate(layers)


def hex_layer_positions(rng, n: int, radius: float, max_gap: float) -> np.ndarray:
    """``[K, 3]``, K <= n: a hexagonal close-packed patch a×b on the ground (a parallelogram
    of the triangular lattice, drawn among those that leave room for a second layer in n; a
    row of n below 5 spheres), and a second layer (:data:`LATTICE_LAYERS`) in its hollows over
    the upward or the downward triangles at random; gaps :func:`contact_gap` in the layer and
    between the layers."""
    span = range(2, n + 1)
    fits = [(a, b) for a in span for b in span if a * b + (a - 1) * (b - 1) <= n] or [(n, 1)]
    a, b = fits[int(rng.integers(len(fits)))]
    step = 2 * radius + contact_gap(rng, max_gap)
    e1, e2 = np.array([step, 0.0]), np.array([step / 2, step * np.sqrt(3) / 2])
    ij = np.stack(np.meshgrid(np.arange(a), np.arange(b), indexing="ij"), -1).reshape(-1, 2)
    xy = ij @ np.stack([e1, e2])
    out = [np.c_[xy, np.full(len(xy), radius)]]
    rise = np.sqrt((2 * radius + contact_gap(rng, max_gap)) ** 2 - step**2 / 3)
    while True:
        a, b = a - 1, b - 1
        if a < 1 or b < 1 or sum(map(len, out)) + a * b > n or len(out) == LATTICE_LAYERS:
            break
        ij = np.stack(np.meshgrid(np.arange(a), np.arange(b), indexing="ij"), -1).reshape(-1, 2)
        third = (e1 + e2) / 3 if rng.uniform() < 0.5 else 2 * (e1 + e2) / 3
        xy = out[-1][0, :2] + ij @ np.stack([e1, e2]) + third
        out.append(np.c_[xy, np.full(len(xy), out[-1][0, 2] + rise)])
    pos = np.concatenate(out)
    pos[:, :2] -= pos[:, :2].mean(0)
    return pos


def deposit_positions(rng, n: int, r_min: float, r_max: float, max_gap: float):
    """``(pos [n, 3], radius [n])``: spheres of radii U[r_min, r_max] laid one by one, each
    (with odds 2 : 1 when one exists) in a stable hollow of three laid spheres (touching them
    all at gaps :func:`contact_gap`, its centre above their triangle), else on the ground
    beside a random laid ground sphere. Mixed radii make every support angle from a few
    degrees (over the largest of three unequal supports) to about 60°."""
    radius = rng.uniform(r_min, r_max, size=n)
    pos = np.zeros((n, 3))
    pos[0, 2] = radius[0]
    for i in range(1, n):
        hollows = _hollows(rng, pos[:i], radius[:i], radius[i], max_gap)
        if len(hollows) and rng.uniform() < 2 / 3:
            pos[i] = hollows[int(rng.integers(len(hollows)))]
        else:
            pos[i] = _beside(rng, pos[:i], radius[:i], radius[i], max_gap)
    pos[:, :2] -= pos[:, :2].mean(0)
    return pos, radius


def _beside(rng, pos, radius, r: float, max_gap: float) -> np.ndarray:
    """A ground position of a sphere of radius r touching (gap) a random ground sphere."""
    ground = np.flatnonzero(np.isclose(pos[:, 2], radius))
    for _ in range(TRIES):
        k = int(rng.choice(ground))
        reach = radius[k] + r + contact_gap(rng, max_gap)
        flat = np.sqrt(reach**2 - (radius[k] - r) ** 2)
        a = rng.uniform(0, 2 * np.pi)
        x = np.array([*(pos[k, :2] + flat * np.array([np.cos(a), np.sin(a)])), r])
        if _clear(pos, radius, x, r):
            return x
    raise SceneError(f"rest layout: no ground place for sphere {len(pos) + 1} in {TRIES} tries")


def _hollows(rng, pos, radius, r: float, max_gap: float) -> np.ndarray:
    """``[H, 3]``: the centres where a sphere of radius r rests on three of ``pos`` (each
    touching it at its own gap) stably (its centre's horizontal projection inside their
    triangle by :data:`INSIDE_MARGIN`, above all three) and overlapping none."""
    m = len(pos)
    if m < 3:
        return np.zeros((0, 3))
    i, j, k = np.array(list(combinations(range(m), 3))).T
    reach = radius + r + max_gap  # a sphere touching a and b has them this close at most

    def near(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.linalg.norm(pos[a] - pos[b], axis=1) <= reach[a] + reach[b]

    keep = near(i, j) & near(i, k) & near(j, k)
    out = []
    for a, b, c in zip(i[keep], j[keep], k[keep], strict=True):
        support = pos[[a, b, c]]
        dist = radius[[a, b, c]] + r + [contact_gap(rng, max_gap) for _ in range(3)]
        x = _trilaterate(support, dist)
        if x is not None and _stable(x, support) and _clear(pos, radius, x, r):
            out.append(x)
    return np.asarray(out).reshape(-1, 3)


def _trilaterate(p: np.ndarray, d: np.ndarray) -> np.ndarray | None:
    """The upper of the two points at distances ``d [3]`` from ``p [3, 3]`` (None if none)."""
    ex = p[1] - p[0]
    span = np.linalg.norm(ex)
    ex /= span
    off = p[2] - p[0]
    u = ex @ off
    ey = off - u * ex
    if np.linalg.norm(ey) < 1e-9:
        return None
    v = np.linalg.norm(ey)
    ey /= v
    x = (d[0] ** 2 - d[1] ** 2 + span**2) / (2 * span)
    y = (d[0] ** 2 - d[2] ** 2 + u**2 + v**2 - 2 * u * x) / (2 * v)
    h2 = d[0] ** 2 - x**2 - y**2
    if h2 <= 0:
        return None
    ez = np.cross(ex, ey)
    ez = ez if ez[2] >= 0 else -ez
    return p[0] + x * ex + y * ey + np.sqrt(h2) * ez


def _stable(x: np.ndarray, support: np.ndarray) -> bool:
    """Above its three supports, its horizontal projection inside their triangle."""
    if np.any(support[:, 2] >= x[2]):
        return False
    t = np.c_[support[:, :2], np.ones(3)].T  # barycentric: t @ w = [x, y, 1]
    try:
        w = np.linalg.solve(t, np.r_[x[:2], 1.0])
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(w > INSIDE_MARGIN))


def rest_layout(rng, n: int, r_min: float, r_max: float, max_gap: float):
    """``(pos [K, 3], radius [K])``, K <= n: one of :data:`REST_KINDS` with equal odds (a
    pyramid and hexagonal layers of one radius U[r_min, r_max])."""
    kind = REST_KINDS[int(rng.integers(len(REST_KINDS)))]
    if kind == "column":
        return column_positions(rng, n, r_min, r_max, max_gap)
    if kind == "deposit":
        return deposit_positions(rng, n, r_min, r_max, max_gap)
    r = float(rng.uniform(r_min, r_max))
    layout = pyramid_positions if kind == "pyramid" else hex_layer_positions
    pos = layout(rng, n, r, max_gap)
    return pos, np.full(len(pos), r)


def ball_vectors(rng, n: int, size: float) -> np.ndarray:
    """``[n, 3]`` vectors uniform in a ball of radius ``size``."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v * size * rng.uniform(size=(n, 1)) ** (1 / 3)
