"""The terms of the training loss (module doc of :mod:`physgnn.training.lit`): the masked MSE
of the normalised outputs, the energy increase of a predicted step and the rest decision's
cross-entropy."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from physgnn.data.state import scene_of_sphere
from physgnn.models.contact_inputs import ballistic_velocity
from physgnn.models.learned import LearnedSimulator
from physgnn.physics.energy import scene_energy, scene_weight
from physgnn.physics.integrator import euler_step


def energy_increase(state, vel_next: torch.Tensor, mean_vel=None) -> torch.Tensor:
    """``[B]``: ``max(E_{t+1} − E_t, 0) / Σ m g`` of every scene (metres of height).

    ``vel_next [N, 3]`` is the predicted ``v̂_{t+1}``; ``E_{t+1}`` uses the position
    ``p_t + dt·ū`` the step moves to (``mean_vel`` ū; None: ``v̂_{t+1}``, Euler) and
    ``v̂_{t+1}``; ``E_t`` uses ``p_t`` and ``v_t``."""
    n_scenes = state.num_graphs if hasattr(state, "num_graphs") else 1
    batch = scene_of_sphere(state)
    moved = vel_next if mean_vel is None else mean_vel
    pos_next, _ = euler_step(state.pos, state.quat, moved, moved, state.scene_dt, rotate=False)
    args = (state.mass, state.radius, batch, n_scenes)
    e_now = scene_energy(state.pos, state.vel[:, 0], *args)
    e_next = scene_energy(pos_next, vel_next, *args)
    return torch.relu(e_next - e_now) / scene_weight(state.mass, batch, n_scenes)


def masked_mse(
    pred: torch.Tensor,
    target: torch.Tensor,
    rotating: torch.Tensor,
    counted: torch.Tensor | None = None,
    angular: tuple[slice, ...] | None = None,
) -> torch.Tensor:
    """Mean squared error of ``[N, C]`` outputs, the ``angular`` column ranges (None: the last
    three of six) only where ``rotating [N]``, and only spheres of ``counted [N]`` (bool, or
    float weights: :func:`regime_weights`; default all; 0 when none is)."""
    weight = torch.ones_like(pred)
    for columns in [slice(3, None)] if angular is None else angular:
        weight[:, columns] = rotating[:, None].to(pred.dtype)
    if counted is not None:
        weight = weight * counted[:, None].to(pred.dtype)
    return ((pred - target) ** 2 * weight).sum() / weight.sum().clamp_min(1.0)


def regime_weights(state, simulator, counted, share: float, speed: float) -> torch.Tensor:
    """``[N]`` float: the regression loss's weight of every sphere, so that moving contacts
    carry at least ``share`` of it (module doc of :mod:`physgnn.training.lit`).

    A moving contact: a sphere of ``counted [N]`` (bool; None: all) whose target end velocity
    departs from ballistic flight, ``|v_{t+1} − (v_t + g·dt)| > speed`` (m/s), and which the
    truth does not bring to rest (:meth:`~physgnn.models.learned.LearnedSimulator.rest_target`).
    With ``n_e`` of them among ``n`` counted spheres and ``n_e/n < share``, each gets
    ``share·n/n_e`` and every other counted sphere ``(1 − share)·n/(n − n_e)`` (the weights
    still sum to ``n``); else every counted sphere weighs 1. Computed on the device: nothing
    read back."""
    dtype = state.pos.dtype
    counted = torch.ones_like(state.radius, dtype=torch.bool) if counted is None else counted
    departure = (state.target_vel - ballistic_velocity(state)).norm(dim=1)
    event = counted & (departure > speed) & ~simulator.rest_target(state)
    n, n_e = counted.to(dtype).sum(), event.to(dtype).sum()
    n_o = n - n_e
    boost = (n_e < share * n) & (n_e > 0) & (n_o > 0)
    heavy = torch.where(boost, share * n / n_e.clamp_min(1), 1.0)
    light = torch.where(boost, (1 - share) * n / n_o.clamp_min(1), 1.0)
    return counted.to(dtype) * torch.where(event, heavy, light)


def rest_loss(simulator: LearnedSimulator, state, pred: torch.Tensor, reach) -> torch.Tensor:
    """Binary cross-entropy of the rest logit (the ``rest`` block of ``pred``) against
    :meth:`~physgnn.models.learned.LearnedSimulator.rest_target`, over the spheres in ``reach``
    (all when None); 0 without a rest decision."""
    if not simulator.contacts.rest_decision:
        return pred.new_zeros(())
    label = simulator.rest_target(state).to(pred.dtype)
    logit = simulator.outputs.take(pred, "rest")[:, 0]
    each = F.binary_cross_entropy_with_logits(logit, label, reduction="none")
    if reach is None:
        return each.mean()
    weight = reach.to(pred.dtype)
    return (each * weight).sum() / weight.sum().clamp_min(1.0)
