"""The plane's tangential answer stays in the friction cone (``model.contacts.friction_cone``).

A plane pushes a sphere along its normal (the planes' floor, :mod:`physgnn.models.floor`, and
the normal part of the node decoder's own change) and along the plane only by friction, which
Coulomb's law bounds: a tangential impulse at most ``μ`` times the normal one, ``μ = μ_i·μ_s``
the engine's product of the sphere's and the plane's lateral friction. The network learned its
answer from examples, and where they are few it breaks the law: the shipped model slowed a
frictionless sphere sliding on a frictionless ground at 4 m/s by 0.37 m/s every other frame and
spun it up, where the engine keeps it sliding at 4 m/s.

For a sphere a plane presses, with ``n`` the direction of the floor's change of its velocity
``Δ_floor`` (the plane's push; the sum of the planes' where several press it), the normal
impulse per unit mass is ``J_n = |Δ_floor| + max(o·n, −|Δ_floor|)`` with ``o [N, 3]`` the node
decoder's own change, and its tangential part ``o_t = o − (o·n)·n`` is scaled by
``s = min(1, μ·J_n / |o_t|)``; the own change of ω by the same ``s`` (the torque of that
friction, and rolling and spinning friction, which the engine also bounds by the normal
impulse). So a frictionless plane stops no sliding and spins nothing; a sliding sphere slows by
at most ``μ·g·dt`` a frame on level ground. Rollouts only, as the energy guard
(:mod:`physgnn.models.energy_guard`): the loss teaches the network the law from the truth,
which keeps it.
"""

from __future__ import annotations

import torch


def sphere_friction(state, graph) -> torch.Tensor:
    """``[N]``: every sphere's largest ``μ_i·μ_s`` over the planes its graph edges reach (0
    without any)."""
    plane, sphere = graph.ps_index
    mu = state.material_params[sphere, 1] * state.plane_materials[plane, 1]
    most = torch.zeros_like(state.radius)
    return most.scatter_reduce(0, sphere, mu, "amax")


def friction_cone(
    floor_change: torch.Tensor, own_vel: torch.Tensor, own_ang: torch.Tensor, mu: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(own_vel, own_ang)`` ``[N, 3]`` each in the cone (module doc): ``floor_change
    [N, 3]`` the planes' floor's change of the velocity, ``mu [N]`` the spheres' friction
    (:func:`sphere_friction`)."""
    push = floor_change.norm(dim=1, keepdim=True)
    normal = floor_change / push.clamp_min(1e-12)
    along = (own_vel * normal).sum(1, keepdim=True)
    tangential = own_vel - along * normal
    support = push + torch.maximum(along, -push)
    reach = mu[:, None] * support
    size = tangential.norm(dim=1, keepdim=True)
    scale = torch.where(size > reach, reach / size.clamp_min(1e-12), torch.ones_like(size))
    return along * normal + scale * tangential, scale * own_ang
