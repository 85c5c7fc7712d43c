"""The invariances of rigid contact, checked on analytic scenes (no engine needed).

Each check rolls the learned simulator out from exact seed frames and compares it with what
physics requires whatever the training data held; every row states its limit and whether it
passed. Checks (``kind`` of a row):

- ``flying_block``: a block of ``4×3×2`` spheres (radius 0.5 m, 0.1 m gaps) far above the
  ground, all with one velocity (2, −1, 3) m/s: nothing touches, so every pair distance must
  stay the same and every velocity must change by exactly ``−g·dt`` per frame. ``value`` is the
  largest change of a neighbour pair's distance as a share of its gap (limit 10 %);
  ``value2`` the largest error of a frame's ``Δv_z`` as a share of ``g·dt`` (limit 2 %).
- ``resting_grid``: a 5 × 5 grid of touching spheres (radius 0.75 m) at rest on the ground,
  at the training density and at 1 kg each: nothing may move. ``value``: the largest
  displacement after ``frames`` frames, in radii (limit 1).
- ``sliding_row``: 5 touching spheres (radius 0.75 m) in a row on a frictionless ground, all
  sliding at 2 m/s along the row for 50 frames: nothing acts between them, so the row must
  keep its shape, though the network sees each sphere's velocity relative to the ground in
  its node latents. ``value``: the largest change of a neighbour distance, in radii (limit
  0.1, ours).
- ``collision``: a frictionless head-on collision in the air of spheres of radius 0.5 and
  1.0 m (mass ratio 1 : 8), closing at 5 m/s: the momentum along the impact line (x) must be
  kept. ``value``: ``|P_x(end) − P_x(0)| / Σ m |v_x(0)|`` (limit 1 %).
- ``ground_collision``: the same pair on a frictionless ground, sliding towards each other
  (their centres at their own heights, so the impact pushes the small one down and the big one
  up): the ground pushes only along z, so the momentum along x must be kept across the impact
  and the slide. ``value`` as ``collision``'s, over 20 frames (limit 1 %).
- ``bounce``: rows of :func:`physgnn.evaluation.bounce.bounce_rows` for restitutions 0.1–0.9
  at one friction and masses 1 kg, the training density's and 10 t: ``value`` the apex over
  ``e²·H`` (limit: within 10 % of 1).

A diverged rollout fails its check (``value`` NaN).
"""

from __future__ import annotations

import itertools

import numpy as np

from physgnn.evaluation.bounce import bounce_rows
from physgnn.evaluation.freefall import ballistic, sphere_mass
from physgnn.physics.energy import G
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout

BLOCK_LIMITS = (0.10, 0.02)  # pair distance change / gap; Δv_z error / (g·dt)
REST_LIMIT = 1.0  # radii
MOMENTUM_LIMIT = 0.01
ROW_LIMIT = 0.1  # radii
BOUNCE_LIMIT = 0.10
BOUNCE_MASSES = (1.0, None, 10_000.0)  # kg; None: density 1 000 (the training density)
# restitution 0.1-0.9 at one friction: what the restitution alone does (the training data
# draws them independently)
BOUNCE_MATERIALS = tuple((e, 0.5, 0.01, 0.01) for e in (0.1, 0.3, 0.5, 0.7, 0.9))


def flying_block(frames: int = 30, dt: float = 0.1) -> Trajectory:
    """The ``flying_block`` scene of the module doc."""
    r, gap = 0.5, 0.1
    cells = np.array(list(itertools.product(range(4), range(3), range(2))), np.float64)
    pos0 = cells * (2 * r + gap) + [0.0, 0.0, 200.0]
    n = len(pos0)
    vel0 = np.tile([2.0, -1.0, 3.0], (n, 1))
    radius = np.full(n, r)
    return ballistic(
        "flying_block", pos0, vel0, radius, sphere_mass(radius), (0.5, 0.7, 0.01, 0.01), frames, dt
    )


def resting_grid(mass: float | None, frames: int, dt: float = 0.1) -> Trajectory:
    """The ``resting_grid`` scene: 25 touching spheres at rest (``mass`` kg each; None: the
    training density)."""
    r = 0.75
    xy = np.array(list(itertools.product(range(5), range(5))), np.float64) * 2 * r
    pos0 = np.concatenate([xy, np.full((25, 1), r)], axis=1)
    radius = np.full(25, r)
    masses = sphere_mass(radius) if mass is None else np.full(25, float(mass))
    material = (0.5, 0.7, 0.01, 0.01)  # resting, not falling: the ground holds them
    return ballistic(
        "resting_grid", pos0, np.zeros((25, 3)), radius, masses, material, frames, dt, fall=False
    )


def collision(frames: int = 12, dt: float = 0.1) -> Trajectory:
    """The ``collision`` scene: radius 0.5 at x = 0 moving +4 m/s, radius 1.0 at 1.5 m of
    gap moving −1 m/s, 50 m up, frictionless (restitution 0.5)."""
    radius = np.array([0.5, 1.0])
    pos0 = np.array([[0.0, 0.0, 50.0], [0.5 + 1.0 + 1.5, 0.0, 50.0]])
    vel0 = np.array([[4.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    return ballistic(
        "collision", pos0, vel0, radius, sphere_mass(radius), (0.5, 0.0, 0.0, 0.0), frames, dt
    )


def ground_collision(frames: int = 20, dt: float = 0.1) -> Trajectory:
    """The ``ground_collision`` scene: the ``collision`` pair resting on a frictionless ground,
    radius 0.5 at x = 0 sliding +4 m/s, radius 1.0 at 1.5 m of gap sliding −1 m/s (exact
    frames: uniform sliding, until the impact)."""
    radius = np.array([0.5, 1.0])
    pos0 = np.array([[0.0, 0.0, 0.5], [0.5 + 1.0 + 1.5, 0.0, 1.0]])
    vel0 = np.array([[4.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    mass, material = sphere_mass(radius), (0.5, 0.0, 0.0, 0.0)
    return ballistic("ground_collision", pos0, vel0, radius, mass, material, frames, dt, fall=False)


def sliding_row(frames: int = 50, dt: float = 0.1) -> Trajectory:
    """The ``sliding_row`` scene of the module doc (exact frames: uniform sliding)."""
    r = 0.75
    pos0 = np.array([[2 * r * k, 0.0, r] for k in range(5)])
    vel0 = np.tile([2.0, 0.0, 0.0], (5, 1))
    radius = np.full(5, r)
    material = (0.5, 0.0, 0.0, 0.0)  # frictionless, on the ground, not falling
    return ballistic(
        "sliding_row", pos0, vel0, radius, sphere_mass(radius), material, frames, dt, fall=False
    )


def _velocities(pos: np.ndarray, dt: float) -> np.ndarray:
    """``[T−1, N, 3]`` finite-difference velocities of ``pos [T, N, 3]``."""
    return np.diff(np.asarray(pos, np.float64), axis=0) / dt


def block_errors(pred, truth: Trajectory) -> tuple[float, float]:
    """``(pair change / gap, Δv_z error / (g·dt))`` of a flying block's rollout (module doc)."""
    pos0 = truth.pos[0]
    dist0 = np.linalg.norm(pos0[:, None] - pos0[None], axis=-1)
    gap0 = dist0 - truth.radius[:, None] - truth.radius[None]
    i, j = np.nonzero(np.triu(gap0 < 1.5 * gap0[np.triu_indices(len(pos0), 1)].min(), 1))
    pos = np.asarray(pred.pos, np.float64)
    dist = np.linalg.norm(pos[:, i] - pos[:, j], axis=-1)
    change = np.abs(dist - dist0[i, j]).max() / gap0[i, j].min()
    dvz = np.diff(_velocities(pos, truth.dt)[..., 2], axis=0)[int(pred.start) - 1 :]
    dvz_error = np.abs(dvz + G * truth.dt).max() / (G * truth.dt)
    return float(change), float(dvz_error)


def invariance_rows(name: str, simulator, rest_frames: int = 2000, **kwargs) -> list[dict]:
    """Every check of the module doc for one learned run (keyword arguments go to
    :func:`physgnn.rollout.rollout`); ``rest_frames``: the resting grids' length."""
    block, hit, row, ground = flying_block(), collision(), sliding_row(), ground_collision()
    grids = [resting_grid(None, rest_frames), resting_grid(1.0, rest_frames)]
    preds = rollout(simulator, [block, hit, row, ground, *grids], **kwargs)
    rows = [_block_row(name, preds[0], block), _collision_row(name, preds[1], hit)]
    rows += [_row_row(name, preds[2], row)]
    rows += [_collision_row(name, preds[3], ground, "ground_collision", "on a frictionless ground")]
    rows += [_rest_row(name, p, g) for p, g in zip(preds[4:], grids, strict=True)]
    for mass in BOUNCE_MASSES:
        bounces = bounce_rows(name, simulator, BOUNCE_MATERIALS, 10.0, 0.1, 0.75, mass, **kwargs)
        rows += [_bounce_row(b) for b in bounces]
    return rows


def _row(name, kind, setting, value, limit, passed, diverged, value2=float("nan")) -> dict:
    """One row of ``invariance.csv``; a check whose rollout diverged (step ``diverged``) fails."""
    return {
        "run": name,
        "kind": kind,
        "setting": setting,
        "value": value,
        "value2": value2,
        "limit": limit,
        "passed": bool(passed and diverged is None),
        "diverged_at": diverged,
    }


def _block_row(name, pred, truth) -> dict:
    change, dvz = block_errors(pred, truth) if pred.diverged_at is None else (np.nan, np.nan)
    ok = change <= BLOCK_LIMITS[0] and dvz <= BLOCK_LIMITS[1]
    return _row(
        name,
        "flying_block",
        "24 spheres, 0.1 m gaps, v = (2, -1, 3) m/s",
        change,
        BLOCK_LIMITS[0],
        ok,
        pred.diverged_at,
        dvz,
    )


def _collision_row(name, pred, truth, kind: str = "collision", where: str = "in the air") -> dict:
    vel = _velocities(pred.pos, truth.dt)[..., 0]
    momentum = vel @ truth.mass
    scale = float(np.abs(truth.vel[0, :, 0]) @ truth.mass)
    error = abs(momentum[-1] - momentum[0]) / scale if pred.diverged_at is None else np.nan
    return _row(
        name,
        kind,
        f"radii 0.5 / 1.0 (mass 1 : 8), frictionless, {where}",
        float(error),
        MOMENTUM_LIMIT,
        error <= MOMENTUM_LIMIT,
        pred.diverged_at,
    )


def _row_row(name, pred, truth) -> dict:
    pos = np.asarray(pred.pos, np.float64)
    dist = np.linalg.norm(np.diff(pos, axis=1), axis=-1)  # [T, 4] neighbour distances
    change = np.abs(dist - dist[0]).max() / truth.radius[0] if pred.diverged_at is None else np.nan
    return _row(
        name,
        "sliding_row",
        "5 touching spheres at 2 m/s, frictionless",
        float(change),
        ROW_LIMIT,
        change <= ROW_LIMIT,
        pred.diverged_at,
    )


def _rest_row(name, pred, truth) -> dict:
    moved = np.linalg.norm(np.asarray(pred.pos[-1], np.float64) - truth.pos[0], axis=-1)
    drift = float(moved.max() / truth.radius.max()) if pred.diverged_at is None else np.nan
    setting = f"25 spheres, {truth.mass[0]:.4g} kg each, {truth.n_frames} frames"
    ok = drift <= REST_LIMIT
    return _row(name, "resting_grid", setting, drift, REST_LIMIT, ok, pred.diverged_at)


def _bounce_row(b: dict) -> dict:
    ratio = b["ratio"]
    ok = abs(ratio - 1.0) <= BOUNCE_LIMIT
    setting = f"e = {b['restitution']:g}, {b['mass']:.4g} kg"
    return _row(b["run"], "bounce", setting, ratio, BOUNCE_LIMIT, ok, b["diverged_at"])
