"""The learned rest decision (``rest_decision=True``, the default model).

Resting spheres are 72 % of the training set's sphere-frames, and 1 radius of creep over
2 000 frames is 0.0025 m/s: below what a regression of Δv, scaled by bounces (σ ≈ 0.16–1.07
m/s), resolves. So the network has a seventh output, the logit of "at rest next frame", trained
by binary cross-entropy against :func:`rest_target`; a sphere in reach of a contact that it
calls at rest gets ``v = ω = 0`` exactly (:func:`at_rest`). The hand-written sleeping of
:mod:`physgnn.models.sleeping` stays a separate, opt-in effect.
"""

from __future__ import annotations

import torch

from physgnn.physics.energy import G


def rest_target(state, rest_speed: float) -> torch.Tensor:
    """``[N]`` bool: spheres whose target next motion is rest, ``|v_{t+1}| < rest_speed`` and
    ``|ω_{t+1}|·r < rest_speed`` (m/s)."""
    still = torch.linalg.vector_norm(state.target_vel, dim=1) < rest_speed
    spin = torch.linalg.vector_norm(state.target_angvel, dim=1) * state.radius
    return still & (spin < rest_speed)


def still_along_the_ground(state, vel: torch.Tensor, rest_speed: float) -> torch.Tensor:
    """``[N]`` bool: spheres whose own answer ``vel [N, 3]`` (the end velocity before the rest
    decision) moves along the ground slowly enough that friction could stop it within the
    frame: ``|v_xy| < max(rest_speed, min(½, μ)·g·dt)``, ``μ`` the sphere's lateral friction
    (the most any contact of it can have: the engine multiplies it by the other side's, at most
    1). Vertically a sphere at rest may be answered up to a frame of gravity (the regression
    leaves support to the rest decision); along the ground only friction can take its speed, so
    a faster answer is one the logit disagrees with. The shipped model stopped a sphere leaving
    a frictionless head-on at 1.46 m/s, and a pair sliding apart on a frictionless ground, and
    their momentum went with them."""
    horizontal = torch.linalg.vector_norm(vel[:, :2], dim=1)
    friction = state.material_params[:, 1].clamp(max=0.5)
    return horizontal < torch.clamp(friction * G * state.scene_dt, min=rest_speed)


def at_rest(logit: torch.Tensor, reach=None) -> torch.Tensor:
    """``[N]`` bool: spheres that the rest decision stops, ``logit [N] > 0`` and in ``reach
    [N]`` of a contact (None: every sphere)."""
    rest = logit > 0
    return rest if reach is None else rest & reach
