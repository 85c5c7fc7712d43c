"""Metrics of frame series: energy and its gain, position error, Chamfer distance, rotation
error, momentum drift and the drift of spheres that should rest (definitions in
:mod:`physgnn.metrics`)."""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from physgnn.metrics import checks
from physgnn.metrics.checks import MetricError, frames, per_sphere, same_shape
from physgnn.physics import quaternion as Q
from physgnn.physics.energy import G, sphere_energy

# E_0 below this fraction of Σ m·g·r counts as zero initial energy.
_ZERO_ENERGY = 1e-6


def energy_series(pos, vel, mass, radius, g: float = G) -> np.ndarray:
    """Total kinetic + potential energy of every frame. pos, vel ``[T, N, 3]`` → ``[T]`` (J)."""
    pos, vel = frames(pos, "pos"), frames(vel, "vel")
    same_shape(pos, vel)
    n = pos.shape[1]
    mass, radius = per_sphere(mass, n, "mass"), per_sphere(radius, n, "radius")
    t = torch.from_numpy
    return sphere_energy(t(pos), t(vel), t(mass), t(radius), g).sum(-1).numpy()


def energy_scale(mass, radius, g: float = G) -> float:
    """``Σ m·g·r``: the divisor of the energy gain when the initial energy is zero."""
    return float(np.sum(np.asarray(mass, np.float64) * g * np.asarray(radius, np.float64)))


def energy_gain(energy, scale: float | None = None) -> float:
    """``Σ_k max(0, E_{k+1} − E_k) / E_0``; divided by ``scale`` (``Σ m·g·r``) instead when
    ``E_0 ≤ 1e-6·scale``. energy ``[T]``. Zero initial energy without a scale is an error."""
    e = _energy(energy)
    return float(np.clip(np.diff(e), 0.0, None).sum()) / _energy_unit(e, scale)


def energy_rise(energy, scale: float | None = None) -> float:
    """``max_k (E_k − E_0) / E_0``, how far the energy ever climbs above its start (0 when it
    never does); same divisor as :func:`energy_gain`. energy ``[T]``."""
    e = _energy(energy)
    return max(0.0, float(e.max() - e[0])) / _energy_unit(e, scale)


def _energy(energy) -> np.ndarray:
    e = np.asarray(energy, dtype=np.float64)
    if e.ndim != 1 or e.size == 0:
        raise MetricError(f"energy series must have shape [T] with T >= 1, got {list(e.shape)}")
    if not np.isfinite(e).all():
        raise MetricError(f"energy series has NaN or inf at frame {int(np.argmin(np.isfinite(e)))}")
    return e


def _energy_unit(e: np.ndarray, scale: float | None) -> float:
    """``E_0``, or ``scale`` when ``E_0`` is zero (float noise) or negative."""
    floor = 0.0 if scale is None else _ZERO_ENERGY * scale
    if e[0] > floor:
        return float(e[0])
    if scale is None or scale <= 0:
        raise MetricError(
            f"initial energy is {e[0]:.3g} <= 0: pass scale = sum(m*g*r) to normalise"
        )
    return float(scale)


# --------------------------------------------------------------------------------- accuracy
def position_mse(pred, true) -> float:
    """Mean over frames and spheres of ``|p̂ − p|²``. ``[T, N, 3]`` × ``[T, N, 3]``."""
    pred, true = frames(pred, "pred pos"), frames(true, "true pos")
    same_shape(pred, true)
    return float(((pred - true) ** 2).sum(-1).mean())


def mse_at(pred, true, k: int) -> float:
    """Position MSE of frame ``k`` only (mean over spheres)."""
    pred, true = frames(pred, "pred pos"), frames(true, "true pos")
    same_shape(pred, true)
    if not 0 <= k < pred.shape[0]:
        raise MetricError(f"frame {k} is outside the {pred.shape[0]} frames given")
    return float(((pred[k] - true[k]) ** 2).sum(-1).mean())


def _nearest_sq(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared distance from each point of a ``[T, N, 3]`` to the nearest of b ``[T, M, 3]``
    and back: ``([T, N], [T, M])``."""
    t_count, n, m = a.shape[0], a.shape[1], b.shape[1]
    if t_count * n * m <= checks.BRUTE_FORCE_MAX:
        d2 = ((a[:, :, None, :] - b[:, None, :, :]) ** 2).sum(-1)  # [T, N, M]
        return d2.min(2), d2.min(1)
    ab = np.stack([cKDTree(bt).query(at)[0] for at, bt in zip(a, b, strict=True)])
    ba = np.stack([cKDTree(at).query(bt)[0] for at, bt in zip(a, b, strict=True)])
    return ab**2, ba**2


def chamfer(pred, true) -> float:
    """Symmetric squared Chamfer distance averaged over frames (report §4.2).

    pred ``[T, N, 3]``, true ``[T, M, 3]``: mean over frames of
    ``mean_i min_j |p̂_i − p_j|² + mean_j min_i |p_j − p̂_i|²``.
    """
    pred, true = frames(pred, "pred pos"), frames(true, "true pos")
    if pred.shape[0] != true.shape[0]:
        raise MetricError(f"prediction has {pred.shape[0]} frames, truth {true.shape[0]}")
    ab, ba = _nearest_sq(pred, true)
    return float((ab.mean(1) + ba.mean(1)).mean())


def rotation_error(q_pred, q_true) -> float:
    """Mean geodesic angle (rad) between orientations ``[T, N, 4]`` (q and −q are equal)."""
    a, b = frames(q_pred, "pred quat", 4), frames(q_true, "true quat", 4)
    same_shape(a, b)
    return float(Q.geodesic_angle(torch.from_numpy(a), torch.from_numpy(b)).mean())


def momentum_drift(vel, mass) -> float:
    """Largest change of the centre-of-mass velocity ``|Σm·v_k − Σm·v_0| / Σm`` (m/s) over
    the frames; meaningful only when no external force acts. vel ``[T, N, 3]``."""
    vel = frames(vel, "vel")
    mass = per_sphere(mass, vel.shape[1], "mass")
    momentum = (mass[:, None] * vel).sum(1)  # [T, 3]
    return float(np.linalg.norm(momentum - momentum[0], axis=-1).max() / mass.sum())


def resting_mask(pos, radius, tol: float = 0.01) -> np.ndarray:
    """Spheres that never move more than ``tol`` radii from their first position ``[N]``."""
    pos = frames(pos, "pos")
    radius = per_sphere(radius, pos.shape[1], "radius")
    return (np.linalg.norm(pos - pos[0], axis=-1) <= tol * radius).all(0)


def rest_drift(pos, radius, mask) -> float | None:
    """Largest displacement from the first frame, in radii, of the spheres in ``mask`` ``[N]``
    (those that should stay at rest); None when the mask is empty."""
    pos = frames(pos, "pos")
    radius = per_sphere(radius, pos.shape[1], "radius")
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return None
    disp = np.linalg.norm(pos[:, mask] - pos[0, mask], axis=-1) / radius[mask]
    return float(disp.max())


def drift_before_hit(pred, true, radius, start: int, tol: float = 0.01) -> np.ndarray:
    """Rest drift of spheres that rest until something hits them: for each sphere the truth
    keeps within ``tol`` radii of its first position through the seed frames ``0..start``,
    the largest displacement (in radii) of ``pred`` from its first frame over the frames
    before the truth moves it. pred / true ``[T, N, 3]`` → ``[R]`` (R such spheres, maybe 0)."""
    pred, true = frames(pred, "pred pos"), frames(true, "true pos")
    radius = per_sphere(radius, pred.shape[1], "radius")
    t = min(len(pred), len(true))
    moved = np.linalg.norm(true[:t] - true[0], axis=-1) > tol * radius  # [T, N]
    rest_until = np.where(moved.any(0), moved.argmax(0), t)  # first frame moved, [N]
    before = np.arange(t)[:, None] < rest_until[None, :]
    disp = np.linalg.norm(pred[:t] - pred[0], axis=-1) / radius
    return np.where(before, disp, 0.0).max(0)[rest_until > start]
