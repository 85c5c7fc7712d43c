"""All metrics of one trajectory, a rollout or the truth: :func:`trajectory_metrics`."""

from __future__ import annotations

import numpy as np

from physgnn.metrics.checks import MetricError, check_tolerance, frames
from physgnn.metrics.penetration import penetration
from physgnn.metrics.series import (
    chamfer,
    drift_before_hit,
    energy_gain,
    energy_scale,
    energy_series,
    momentum_drift,
    mse_at,
    position_mse,
    rest_drift,
    resting_mask,
    rotation_error,
)
from physgnn.physics.energy import G
from physgnn.physics.trajectory import Trajectory

_SCENE_KEYS = ("radius", "mass", "planes", "plane_kind", "effects")


def trajectory_metrics(
    pred: Trajectory,
    true: Trajectory | None = None,
    *,
    tol: float = 0.0,
    horizon: int = 20,
    rest_mask=None,
    rest_tol: float = 0.01,
    g: float = G,
) -> dict:
    """All metrics of one (possibly truncated) trajectory ``pred``, a rollout or the truth.

    The scene arrays (radius, mass, planes, plane_kind, effects) are ``true``'s when given,
    else ``pred``'s. Without ``true`` only the physics metrics are computed. Comparisons use
    the first ``min(T, T_true)`` frames. ``mse{horizon}`` is the MSE at frame
    ``pred.start + horizon``; None when not reached. ``momentum_drift`` only for scenes
    without gravity or surface contact. ``rest_drift`` for the spheres of ``rest_mask``, by
    default those that move less than ``rest_tol`` radii in the truth; ``drift_before_hit``
    (:func:`drift_before_hit`) for those that rest until hit. Keys with nothing to measure
    are None.
    """
    check_tolerance(tol)
    scene = {k: getattr(true if true is not None else pred, k) for k in _SCENE_KEYS}
    missing = [k for k in _SCENE_KEYS[:4] if scene[k] is None]
    if missing:
        raise MetricError(
            f"no scene arrays {missing}: pass the true trajectory or put them in pred"
        )
    if pred.vel is None:
        raise MetricError("pred has no 'vel' (velocities are needed for the energy)")
    out = _physics(pred, scene, tol, g)
    mse_key = f"mse{horizon}"
    out.update(mse=None, **{mse_key: None}, chamfer=None, rotation_error=None)
    out.update(rest_drift=None, drift_before_hit=None)
    pos = frames(pred.pos, "pred pos")
    if true is None:
        if rest_mask is not None:
            out["rest_drift"] = rest_drift(pos, scene["radius"], rest_mask)
        return out
    out.update(_accuracy(pos, pred, true, horizon, mse_key))
    radius = scene["radius"]
    if rest_mask is None:
        rest_mask = resting_mask(true.pos, radius, rest_tol)
    out["rest_drift"] = rest_drift(pos, radius, rest_mask)
    hit = drift_before_hit(pos, true.pos, radius, int(pred.start), rest_tol)
    out["drift_before_hit"] = float(hit.max()) if hit.size else None
    return out


def _physics(pred: Trajectory, scene: dict, tol: float, g: float) -> dict:
    """Size, divergence, energy gain, penetration and momentum drift of ``pred``."""
    pos, vel = frames(pred.pos, "pred pos"), frames(pred.vel, "pred vel")
    radius, mass = scene["radius"], scene["mass"]
    energy = energy_series(pos, vel, mass, radius, g)
    effects = scene["effects"]
    free = effects is not None and not (effects.gravity or effects.surface_contact)
    return {
        "n_spheres": int(pos.shape[1]),
        "n_frames": int(pos.shape[0]),
        "diverged_at": pred.diverged_at,
        "energy_gain": energy_gain(energy, energy_scale(mass, radius, g)),
        **penetration(pos, radius, scene["planes"], scene["plane_kind"], tol),
        "momentum_drift": momentum_drift(vel, mass) if free else None,
    }


def _accuracy(pos, pred: Trajectory, true: Trajectory, horizon: int, mse_key: str) -> dict:
    """Position MSE, MSE at ``start + horizon``, Chamfer distance and rotation error."""
    t_count = min(pos.shape[0], true.n_frames)
    p_hat, p_true = pos[:t_count], np.asarray(true.pos[:t_count], np.float64)
    out = {"mse": position_mse(p_hat, p_true), "chamfer": chamfer(p_hat, p_true)}
    if int(pred.start) + horizon < t_count:
        out[mse_key] = mse_at(p_hat, p_true, int(pred.start) + horizon)
    if pred.quat is not None:
        out["rotation_error"] = rotation_error(pred.quat[:t_count], true.quat[:t_count])
    return out
