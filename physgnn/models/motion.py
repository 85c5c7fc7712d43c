"""A learned step's normalised outputs in physical units: the next state's velocities and the
frame's mean motion.

**The engine state** (``model.inputs.engine_state``): the state's velocities are the engine's at
each frame's end (the dataset's ``vel``, ``angvel``), not finite differences of positions. A
finite-difference velocity of a frame that holds an impact is the frame's *mean*, so flight after
a contact would depend on when, inside the frame, the impact happened; the engine's end velocity
makes the state Markov across a contact. The model then predicts the end velocities
``(v_{t+1}, ω_{t+1})`` (the next state) and the frame's mean motion ``ū = Δp/dt``,
``ω̄ = log(q_{t+1} ⊗ q_t⁻¹)/dt`` (what moves the sphere,
:func:`physgnn.physics.integrator.move`) apart, both through the pair-impulse rule
(:mod:`physgnn.models.impulses`). A sphere out of reach of any contact moves in closed form as
the truth's integrator does: semi-implicit Euler at k substeps gives ``v_{t+1} = v_t + g·dt``
and ``ū = v_t + s·g·dt`` with ``s = (k + 1)/(2k)``
(:func:`~physgnn.models.contact_inputs.gravity_share`, k from the training data's metadata;
data without it: the exact parabola, ``s = 1/2``). Data with positions only (the GNS and
LagrangeBench imports) keeps finite differences
(:func:`~physgnn.data.state.has_engine_velocities`).
"""

from __future__ import annotations

import torch

from physgnn.models import contact_inputs, rest
from physgnn.models.energy_guard import guarded
from physgnn.models.floor import contact_directions, plane_floor


def physical_motion(
    sim, state, pred: torch.Tensor, reach=None, supported=None, graph=None
) -> tuple:
    """Normalised output → ``(v_{t+1}, ω_{t+1}, ū, ω̄)``, each ``[N, 3]``: the next
    state's velocities and the frame's mean motion (the same tensors for a
    finite-difference state). Spheres of a scene without rotation keep ``ω_t``. With
    ``gravity_prior``, spheres outside ``reach [N]`` (``sim.in_reach`` of the prediction's
    graph) fly ballistically: ``v + g·dt`` and, with the engine state, the mean
    ``v + s·g·dt``, ``s`` the engine's own share
    (:func:`~physgnn.models.contact_inputs.gravity_share`). The rest decision stops spheres
    that are ``supported [N]`` (None: those in ``reach``; with ``rest_consistent``, outside
    training, only those whose own answer is still along the ground:
    :func:`~physgnn.models.rest.still_along_the_ground`). With
    ``energy_guard``, outside training, the frame's contacts add no energy
    (:mod:`physgnn.models.energy_guard`); given the step's ``graph``, the planes' floor then
    holds the move out of the planes again."""
    out, vel_t, angvel_t = sim.outputs, state.vel[:, 0], state.angvel[:, 0]
    vel = vel_t + out.take(pred, "delta_vel") * sim.delta_vel_std + sim.delta_vel_mean
    spin = out.take(pred, "delta_angvel") * sim.delta_angvel_std
    moves = [vel, angvel_t + spin + sim.delta_angvel_mean]
    if sim.inputs.engine_state:
        mean = out.take(pred, "delta_mean_vel") * sim.delta_vel_std
        spin = out.take(pred, "delta_mean_angvel") * sim.delta_angvel_std
        moves += [vel_t + mean + sim.delta_vel_mean, angvel_t + spin + sim.delta_angvel_mean]
    free = free_motion(sim, state)
    if sim.contacts.gravity_prior:
        if reach is None:
            raise ValueError("gravity_prior needs the spheres in reach of a contact")
        moves = [torch.where(reach[:, None], m, f) for m, f in zip(moves, free, strict=True)]
    rest_now = None
    if sim.contacts.rest_decision:
        rest_now = rest.at_rest(
            out.take(pred, "rest")[:, 0], reach if supported is None else supported
        )
        if sim.contacts.rest_consistent and not sim.training:
            still = rest.still_along_the_ground(state, moves[0], sim.contacts.rest_speed)
            rest_now = rest_now & still
        moves = [torch.where(rest_now[:, None], torch.zeros_like(m), m) for m in moves]
    rotating = sim.rotating(state)[:, None]
    moves[1::2] = [torch.where(rotating, m, angvel_t) for m in moves[1::2]]
    moves = tuple(moves) if sim.inputs.engine_state else (*moves, *moves)
    if sim.contacts.energy_guard and not sim.training:
        free = free if sim.inputs.engine_state else (*free, *free)
        contacts = None if graph is None else contact_directions(graph, state.radius)
        slack = sim.contacts.energy_slack
        moves = guarded(state, free, moves, rest_now, slack, graph, contacts)
        if graph is not None and sim.contacts.plane_floor:
            moves = floored_move(state, graph, moves, sim.inputs.engine_state, contacts)
    return moves


def floored_move(state, graph, moves: tuple, engine_state: bool, contacts=None) -> tuple:
    """``moves`` ``(v, ω, ū, ω̄)`` after the planes' floor of ``graph``
    (:func:`~physgnn.models.floor.plane_floor`; ``contacts``: its ps edges' directions, where
    the caller has them): the move ``ū`` held out of every plane and, where that acted, the end
    velocity ``v`` no longer approaching it; a finite-difference state's velocity is its move."""
    if engine_state:
        mean, end = plane_floor(state, graph, moves[2], moves[0], contacts=contacts)
        return end, moves[1], mean, moves[3]
    mean = plane_floor(state, graph, moves[2], contacts=contacts)[0]
    return mean, moves[1], mean, moves[3]


def free_motion(sim, state) -> list:
    """``[v, ω]`` of free flight (``v_t + g·dt``, ``ω_t``) ``[N, 3]`` each, with the engine
    state also ``[ū, ω̄]``, the mean ``v_t + s·g·dt`` with the engine's own share ``s``
    (:func:`~physgnn.models.contact_inputs.gravity_share`)."""
    vel_t = state.vel[:, 0]
    vel_free, angvel_free = contact_inputs.free_flight(state)
    free = [vel_free, angvel_free]
    if sim.inputs.engine_state:
        free += [vel_t + sim.gravity_share * (vel_free - vel_t), angvel_free]
    return free
