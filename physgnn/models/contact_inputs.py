"""Inputs that state the contact, material values, and gravity as a known prior: the parts of
the default model's input that the report's model (``model=report``) does not have.

**Contact features** (``contact_features=True``): the contact is stated instead of left for
the network to compute. pp edges add the signed gap ``(|p_i − p_j| − r_i − r_j)/ℓ`` and the
normal relative speed ``(v_i − v_j)·n̂_ij / σ_v`` (``n̂_ij`` from j to i; negative when the pair
closes); ps edges add the clearance ``(h − r_i)/ℓ`` (h the clipped signed height of the edge
features), the normal speed ``v_i·n_s / σ_v`` and the tangential speed
``|v_i − (v_i·n_s) n_s| / σ_v`` (ℓ the model's ``length_scale``, σ_v the RMS of the velocity
std). Both pair features are the same for an edge and its reverse, so the paired layout and
the third law hold.

**Relative pair inputs** (``relative_pairs=True``, the default model): pp edges carry only
relative quantities (:func:`pair_inputs`), so a group moving as one exchanges the same
messages whatever its common velocity, and masses enter as the ratio ``m_i / (m_i + m_j)``
(with ``mass_ratio``; the node inputs then hold no mass at all).

**Material features** (``material_features=True``): each sphere's restitution, lateral
friction and 100 × its rolling and spinning friction as node inputs: values, not ids, so a
material no training scene had still means something.

**Gravity prior** (``gravity_prior=True``): a sphere that cannot touch anything before the
next frame moves ballistically, ``v_{t+1} = v_t + g·dt`` and ``ω_{t+1} = ω_t`` exactly,
whatever its mass or size; the network's output is used only for spheres *in reach* of a
contact: with a pp edge, an edge to a wall or static plane (the graph's own reach rule), a
ground clearance within the graph's plane rule (for ``vi``, ``vmax``, ``epsilon``:
``h − r ≤ a_i + ε + g·dt²``, the rule plus the fall that gravity adds within the frame;
``approach`` counts the fall itself), or a contact during the last frame, seen in the velocity
history as ``|v_t − v_{t−1} − g·dt| > RECENT_TOL`` (needs H ≥ 1). The last one matters: a
sphere that bounced inside the last frame interval has a finite-difference velocity that is not its
physical one (the mean over a frame that held the impact), and only the network can tell
what comes next. The network so learns contacts only, and free flight is exact.
"""

from __future__ import annotations

import torch

from physgnn.data.state import scene_of_sphere
from physgnn.graph.builder import ballistic_velocity
from physgnn.physics.energy import G
from physgnn.physics.geometry import edge_plane_depth
from physgnn.physics.scene import EFFECT_NAMES, GROUND

GRAVITY = EFFECT_NAMES.index("gravity")
PP_CONTACT, PS_CONTACT = 2, 3  # features the contact inputs add per pp / ps edge
# m/s: a velocity change this far from g·dt within one frame was a contact (ballistic frames
# of the data and of rollouts agree with g·dt to float rounding, about 1e-4 m/s)
RECENT_TOL = 0.01
# Scale of the material parameters (restitution, lateral, rolling, spinning friction) as node
# inputs: rolling and spinning coefficients are ~0.01, the others ~0.5.
MATERIAL_SCALE = (1.0, 1.0, 100.0, 100.0)


def pp_contact(graph, state, length_scale, speed_scale) -> torch.Tensor:
    """``[E, 2]``: gap / ℓ and ``(v_i − v_j)·n̂_ij`` / σ_v (i the target; a pair of coincident
    spheres has ``n̂ = 0``)."""
    src, dst = graph.pp_index
    normal, gap = _normal_and_gap(graph, state)
    vel = state.vel[:, 0]
    closing = ((vel[dst] - vel[src]) * normal).sum(1, keepdim=True)
    return torch.cat([gap / length_scale, closing / speed_scale], 1)


def _normal_and_gap(graph, state) -> tuple[torch.Tensor, torch.Tensor]:
    """``(n̂_ij [E, 3], gap [E, 1])`` of the pp edges: the unit vector from source j to target
    i (0 for coincident spheres) and ``|p_i − p_j| − r_i − r_j``."""
    src, dst = graph.pp_index
    rel, dist = graph.pp_attr[:, :3], graph.pp_attr[:, 3:4]
    gap = dist - (state.radius[src] + state.radius[dst])[:, None]
    return rel / dist.clamp_min(1e-12), gap


def pair_width(history: int, mass_ratio: bool, materials: bool) -> int:
    """Columns of :func:`pair_inputs` for ``history`` = H + 1 velocities."""
    return 5 + 3 * history + int(mass_ratio) + (2 if materials else 0)


def pair_inputs(
    graph, state, length_scale, speed_scale, history: int, mass_ratio: bool, materials: bool
) -> torch.Tensor:
    """``[E, pair_width(...)]``: the pair's *relative* inputs, none of which changes when a
    common velocity is added to both spheres (Galilean invariance) or every mass is scaled
    (mass-scale invariance); i the target, j the source, ``n̂_ij`` from j to i:

    ``[gap / ℓ, (v_i − v_j)·n̂ / σ_v, |tangential part of v_i − v_j| / σ_v,
    (v_i − v_j) of the ``history`` latest frames / σ_v (3 each), r_i / ℓ, r_j / ℓ]``, then
    ``m_i / (m_i + m_j)`` with ``mass_ratio``, then the pair's restitution ``e_i·e_j`` and
    lateral friction ``μ_i·μ_j`` (Bullet's combination rules) with ``materials``."""
    src, dst = graph.pp_index
    normal, gap = _normal_and_gap(graph, state)
    dv = state.vel[dst, :history] - state.vel[src, :history]  # [E, history, 3]
    along = (dv[:, 0] * normal).sum(1, keepdim=True)
    across = torch.linalg.vector_norm(dv[:, 0] - along * normal, dim=1, keepdim=True)
    radius = torch.stack([state.radius[dst], state.radius[src]], 1) / length_scale
    parts = [gap / length_scale, along / speed_scale, across / speed_scale]
    parts += [dv.flatten(1) / speed_scale, radius]
    if mass_ratio:
        parts.append((state.mass[dst] / (state.mass[dst] + state.mass[src]))[:, None])
    if materials:
        params = state.material_params
        parts.append(params[dst, :2] * params[src, :2])
    return torch.cat(parts, 1)


def ps_contact(graph, state, length_scale, speed_scale) -> torch.Tensor:
    """``[F, 3]``: clearance ``(h − r)`` / ℓ, ``v·n`` / σ_v and the tangential speed / σ_v."""
    ps = graph.ps_attr
    vel, normal, height = ps[:, :3], ps[:, 3:6], ps[:, 9:10]
    clearance = height - state.radius[graph.ps_index[1]][:, None]
    along = (vel * normal).sum(1, keepdim=True)
    across = torch.linalg.vector_norm(vel - along * normal, dim=1, keepdim=True)
    return torch.cat([clearance / length_scale, along / speed_scale, across / speed_scale], 1)


def material_features(state) -> torch.Tensor:
    """``[N, 4]``: the material rows scaled by :data:`MATERIAL_SCALE`, by a Python scalar (a
    tensor of the scales would be a host-to-device copy per call)."""
    params = state.material_params
    return torch.stack([params[:, k] * s for k, s in enumerate(MATERIAL_SCALE)], dim=-1)


def in_reach(state, graph, builder) -> torch.Tensor:
    """``[N]`` bool: spheres that may touch something before the next frame or touched
    something during the last one (module doc): a pp edge, a wall / static ps edge, the ground
    within ``a_i + ε + g·dt²``, or :func:`recent_contact`. ``builder`` is
    the :class:`~physgnn.graph.builder.GraphBuilder` that built ``graph`` (its ε)."""
    n = state.pos.shape[0]
    touched = state.pos.new_zeros(n)
    pp_weight = graph.pp_weight(touched)
    if pp_weight is None:
        pp_weight = state.pos.new_ones(graph.pp_index.shape[1])
    touched.index_add_(0, graph.pp_index[1], pp_weight)
    plane, sphere = graph.ps_index
    bounded = state.plane_kind[plane] != GROUND
    # the edge features' heights are clipped: the clearance from the geometry itself
    depth = edge_plane_depth(
        state.pos, state.radius, state.planes, state.plane_kind, graph.ps_index
    )
    if builder.connectivity == "approach":  # the rule itself counts the fall (v + g·dt)
        normal = state.planes[plane, 3:6]
        near = builder.plane_within_reach(state, sphere, normal, -depth, graph.allowance)
    else:
        dt = state.scene_dt[sphere]
        near = -depth <= graph.allowance[sphere] + builder.epsilon + G * dt * dt
    near = bounded | near
    if graph.masked:  # a fixed-capacity graph's candidates outside the rules
        near = near & graph.ps_mask
    touched.index_add_(0, sphere, near.to(touched.dtype))
    return (touched > 0) | recent_contact(state)


def recent_contact(state) -> torch.Tensor:
    """``[N]`` bool: spheres whose last frame was not ballistic,
    ``|v_t − v_{t−1} − g·dt| > RECENT_TOL`` (all False without a velocity history)."""
    if state.vel.dim() < 3 or state.vel.shape[1] < 2:
        return torch.zeros(state.pos.shape[0], dtype=torch.bool, device=state.pos.device)
    gravity = state.effects[scene_of_sphere(state), GRAVITY].to(state.pos.dtype)
    change = state.vel[:, 0] - state.vel[:, 1]
    change[:, 2] = change[:, 2] + G * state.scene_dt * gravity
    return torch.linalg.vector_norm(change, dim=1) > RECENT_TOL


def free_flight(state) -> tuple[torch.Tensor, torch.Tensor]:
    """``(v_t + g·dt, ω_t)`` ``[N, 3]`` each: the ballistic next velocities (g only in scenes
    with gravity; :func:`~physgnn.graph.builder.ballistic_velocity`)."""
    return ballistic_velocity(state), state.angvel[:, 0]
