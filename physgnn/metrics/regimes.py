"""What a sphere does in one frame, from the truth alone, and the one-step error split by it.

Every sphere-frame ``(i, t → t+1)`` of a true trajectory gets one regime, computed only from
the truth (positions at ``t`` and ``t + 1``, the truth's velocities ``v_t`` and ``v_{t+1}``,
radii, planes, ``dt`` and gravity ``g``), so that every simulator is judged on the same labels.
The velocities are the ones the trajectory stores: the engine's at each frame's end for
generated data (finite differences for data with positions only).

- **free**: no contact impulse acted in the frame, ``|v_{t+1} − v_t − g·dt| <`` :data:`FREE_TOL`
  (0.01 m/s): the engine's velocity changed by gravity alone.
- **flight**: free in ``t → t+1`` and in ``t−1 → t`` (the frame before the first is taken as
  free). **flight_after_contact**: free in ``t → t+1`` but not in ``t−1 → t``: the first frame
  of flight after a frame that held a contact (a finite-difference velocity at ``t`` is the
  mean over that contact frame, not the velocity the sphere leaves it with).

The other regimes are frames that held a contact impulse, in this order of precedence:

- **rest**: ``|v_t|``, ``|v_{t+1}|`` and the frame's mean speed ``|p_{t+1} − p_t|/dt`` all
  below :data:`REST_SPEED` (0.05 m/s).
- a plane is **in reach** when its clearance (distance from the sphere's surface, one-sided as
  :func:`physgnn.physics.geometry.plane_depth`; < 0: depth) at ``t`` or ``t + 1`` is at most
  ``dt·u + |g|·dt² +`` :data:`MARGIN` (0.02 m), ``u`` the larger of ``|v_t·n|`` and
  ``|v_{t+1}·n|``, ``n`` the direction from the plane's closest point to the centre at ``t``;
  a sphere is in reach when their gap at ``t`` or ``t + 1`` is at most ``dt·w + |g|·dt² +
  MARGIN``, ``w`` the larger relative speed ``|v_i − v_j|`` at ``t`` and ``t + 1``.
- **plane_sphere**: a plane and a sphere in reach. **sphere**: a sphere, no plane.
- **rolling**: planes only, and the sphere slides or rolls on each of them: clearance at most
  :data:`TOUCH` (0.02 m) at ``t`` and ``t + 1`` and ``|v·n|`` below :data:`ROLL_NORMAL_SPEED`
  (0.1 m/s) at both. **plane_impact**: planes only, one of them approached or left faster.
- **other**: a contact impulse with nothing in reach (rare: it would flag a rule to revisit).

:func:`regime_labels` labels a trajectory's frames; :func:`tally` and :func:`regime_rows`
turn labels and squared one-step errors into one row per regime (its sphere-frames, their
share, its mean squared error and its share of the summed squared error) and an ``all`` row.
"""

from __future__ import annotations

import numpy as np
import torch

from physgnn.physics.geometry import plane_depth, rectangle_offset

REGIMES = (
    "flight",
    "flight_after_contact",
    "rest",
    "plane_impact",
    "rolling",
    "sphere",
    "plane_sphere",
    "other",
)
ALL = "all"
FREE_TOL = 0.01  # m/s: a velocity change this close to g·dt is no contact
REST_SPEED = 0.05  # m/s
MARGIN = 0.02  # m, added to every reach
TOUCH = 0.02  # m: clearance of a sphere that stays on a plane
ROLL_NORMAL_SPEED = 0.1  # m/s along the plane's normal: rolling, not an impact


def regime_labels(pos, vel, radius, planes, plane_kind, dt: float, gravity) -> np.ndarray:
    """``[T − 1, N]`` int: the index in :data:`REGIMES` of every sphere-frame ``t → t+1``.

    pos, vel ``[T, N, 3]`` (the truth's), radius ``[N]``, planes ``[S, 11]``, plane_kind
    ``[S]``, ``dt`` s, gravity ``[3]`` m/s² (zeros where a scene has none)."""
    pos, vel = np.asarray(pos, np.float64), np.asarray(vel, np.float64)
    g = np.asarray(gravity, np.float64)
    radius = np.asarray(radius, np.float64)
    residual = np.linalg.norm(vel[1:] - vel[:-1] - g * dt, axis=-1)  # [T-1, N]
    free = residual < FREE_TOL
    free_before = np.concatenate([np.ones_like(free[:1]), free[:-1]])
    slack = float(np.linalg.norm(g)) * dt * dt + MARGIN
    mean_speed = np.linalg.norm(pos[1:] - pos[:-1], axis=-1) / dt
    speed = np.linalg.norm(vel, axis=-1)
    rest = (speed[:-1] < REST_SPEED) & (speed[1:] < REST_SPEED) & (mean_speed < REST_SPEED)
    plane_reach, impact = _planes(pos, vel, radius, planes, plane_kind, dt, slack)
    sphere_reach = _spheres(pos, vel, radius, dt, slack)
    return _choose(free, free_before, rest, plane_reach, impact, sphere_reach)


def _choose(free, free_before, rest, plane_reach, impact, sphere_reach) -> np.ndarray:
    """The regimes in their order of precedence (module docstring)."""
    rules = [
        ("flight", free & free_before),
        ("flight_after_contact", free),
        ("rest", rest),
        ("plane_sphere", plane_reach & sphere_reach),
        ("sphere", sphere_reach),
        ("plane_impact", plane_reach & impact),
        ("rolling", plane_reach),
    ]
    labels = np.full(free.shape, REGIMES.index("other"))
    for name, where in reversed(rules):  # the first rule that holds wins
        labels[where] = REGIMES.index(name)
    return labels


def _planes(pos, vel, radius, planes, plane_kind, dt: float, slack: float):
    """``(in reach of a plane, approaching or leaving one)``, each ``[T − 1, N]`` bool."""
    shape = (pos.shape[0] - 1, pos.shape[1])
    reach, impact = np.zeros(shape, bool), np.zeros(shape, bool)
    p, r = torch.from_numpy(pos), torch.from_numpy(radius)
    for row, kind in zip(np.asarray(planes, np.float64), np.asarray(plane_kind), strict=True):
        plane = torch.from_numpy(row)
        clear = -plane_depth(p, r, plane, int(kind)).numpy()  # [T, N]
        offset = rectangle_offset(p, plane).numpy()
        n = offset / np.maximum(np.linalg.norm(offset, axis=-1, keepdims=True), 1e-12)
        normal = np.abs((vel[:-1] * n[:-1]).sum(-1)), np.abs((vel[1:] * n[:-1]).sum(-1))
        near = np.minimum(clear[:-1], clear[1:]) <= dt * np.maximum(*normal) + slack
        stays = np.maximum(clear[:-1], clear[1:]) <= TOUCH
        slides = stays & (np.maximum(*normal) < ROLL_NORMAL_SPEED)
        reach |= near
        impact |= near & ~slides
    return reach, impact


def _spheres(pos, vel, radius, dt: float, slack: float) -> np.ndarray:
    """``[T − 1, N]`` bool: another sphere in reach (one frame at a time: ``N²`` memory)."""
    frames, n = pos.shape[0] - 1, pos.shape[1]
    out = np.zeros((frames, n), bool)
    if n < 2:
        return out
    sum_r = radius[:, None] + radius[None]
    eye = np.eye(n, dtype=bool)
    gap = [np.linalg.norm(pos[0][:, None] - pos[0][None], axis=-1) - sum_r]
    rel = [np.linalg.norm(vel[0][:, None] - vel[0][None], axis=-1)]
    for t in range(frames):
        gap.append(np.linalg.norm(pos[t + 1][:, None] - pos[t + 1][None], axis=-1) - sum_r)
        rel.append(np.linalg.norm(vel[t + 1][:, None] - vel[t + 1][None], axis=-1))
        near = np.minimum(gap[0], gap[1]) <= dt * np.maximum(rel[0], rel[1]) + slack
        out[t] = (near & ~eye).any(-1)
        gap, rel = gap[1:], rel[1:]
    return out


def tally(labels, squared_error) -> tuple[np.ndarray, np.ndarray]:
    """``(sphere-frames [R], summed squared error [R])`` per regime of :data:`REGIMES`.

    labels ``[F, N]`` int, squared_error ``[F, N]`` (m²), the same sphere-frames; add the
    tallies of several trajectories before :func:`regime_rows`."""
    labels = np.asarray(labels).reshape(-1)
    err = np.asarray(squared_error, np.float64).reshape(-1)
    if labels.shape != err.shape:
        raise ValueError(f"{labels.size} labels for {err.size} squared errors")
    counts = np.bincount(labels, minlength=len(REGIMES)).astype(np.int64)
    sums = np.bincount(labels, weights=err, minlength=len(REGIMES))
    return counts, sums


def regime_rows(counts, sums) -> list[dict]:
    """One row per regime, then :data:`ALL`: ``regime, sphere_frames, share_frames, mse,
    share_error`` (mse None where a regime has no sphere-frame; shares of the totals)."""
    counts, sums = np.asarray(counts, np.int64), np.asarray(sums, np.float64)
    total_n, total_e = int(counts.sum()), float(sums.sum())
    rows = []
    for name, n, e in [*zip(REGIMES, counts, sums, strict=True), (ALL, total_n, total_e)]:
        rows.append(
            {
                "regime": name,
                "sphere_frames": int(n),
                "share_frames": n / total_n if total_n else None,
                "mse": e / n if n else None,
                "share_error": e / total_e if total_e > 0 else None,
            }
        )
    return rows
