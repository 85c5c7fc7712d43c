"""Sphere pairs by Newton's law (``model.contacts.pair_newton``, the engine state): a pair that
meets within the frame in free flight leaves the meeting with its contact's restitution, in
closed form, and the network's pair impulses come on top.

Two spheres under one uniform gravity move in a straight line relative to each other: for a pp
pair (i, j) with ``d = p_i − p_j``, ``u = v_i − v_j`` (the engine velocities at the frame's
start) and ``s = r_i + r_j`` the gap closes where ``|d + u·τ| = s``,

    τ = (−d·u − √((d·u)² − |u|²·(|d|² − s²))) / |u|²      (0 where they already touch),

when they approach (``d·u < 0``) and ``τ < dt``. There ``n = (d + u·τ)/|d + u·τ|`` (from j to
i), the speed of arrival is ``w = −u·n > 0`` and Newton's law with ``e = e_i·e_j`` (the engine's
combination of the two restitutions) changes the relative velocity by ``(1 + e)·w`` along n,
shared by the reduced-mass rule:

    Δv_i = m_j/(m_i + m_j)·(1 + e)·w·n,   Δv_j = −m_i/(m_i + m_j)·(1 + e)·w·n,

so momentum is exact, and the impulse passes through both centres (no torque). The end velocity
takes Δv whole, the frame's mean motion ``Δv·(dt − τ)/dt`` (the part of the frame after the
meeting). For an isolated pair that is the engine's frictionless answer; its friction, spin and
the engine's departures from the law are the network's to learn.

Several meetings of one sphere add up (Jacobi): exact for binary collisions, an approximation in
a cluster that the network corrects. A pair with a sphere in reach of a plane is left to the
network: a pair impulse that presses a sphere into a plane needs the plane's answer within the
same law (sequential impulses), which one closed form does not give.

Shapes: ``pp_index [2, E]`` in the paired layout (its first half one direction of every pair),
``free [N]`` bool (no plane in reach), ``weight [E/2]`` (or None) 0 for a fixed-capacity graph's
masked candidates; returns ``(Δv [N, 3], Δū [N, 3])``.
"""

from __future__ import annotations

import torch

from physgnn.models.pair_floor import shared

TINY = 1e-12  # (m/s)²: a relative speed below its root is no approach


def pair_bounces(state, pp_index, free, weight=None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(Δv [N, 3], Δū [N, 3])``: the end velocities' and the frame's mean motion's changes of
    every sphere from the meetings of its pairs by Newton's law (module doc)."""
    half = pp_index.shape[1] // 2
    src, dst = pp_index[:, :half]
    vel = state.vel[:, 0] if state.vel.dim() == 3 else state.vel
    d = state.pos[dst] - state.pos[src]
    u = vel[dst] - vel[src]
    reach = state.radius[dst] + state.radius[src]
    dt = state.scene_dt[dst]
    a = u.square().sum(1)
    b = (d * u).sum(1)
    c = d.square().sum(1) - reach.square()
    root = torch.sqrt(torch.relu(b.square() - a * c))
    tau = torch.where(c > 0, (-b - root) / a.clamp_min(TINY), torch.zeros_like(b))
    meets = (b < 0) & (a > TINY) & (b.square() >= a * c) & (tau < dt) & free[dst] & free[src]
    contact = d + u * tau[:, None]
    n = contact / contact.norm(dim=1, keepdim=True).clamp_min(TINY)
    arrival = torch.relu(-(u * n).sum(1))
    restitution = state.material_params[dst, 0] * state.material_params[src, 0]
    change = (1 + restitution) * arrival * meets.to(arrival.dtype)
    if weight is not None:
        change = change * weight
    m_i, m_j = state.mass[dst], state.mass[src]
    shares = m_j / (m_i + m_j), m_i / (m_i + m_j)
    zero = torch.zeros_like(vel)
    after = ((dt - tau) / dt).clamp(0, 1)
    end = shared(zero, src, dst, n, change, *shares)
    return end, shared(zero, src, dst, n, change * after, *shares)
