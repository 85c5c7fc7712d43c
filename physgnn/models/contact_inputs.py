"""Inputs that state the contact, material values, and gravity as a known prior: the parts of
the default model's input that the report's model (``model=report``) does not have.

Each function writes named blocks of the edge contract (:mod:`physgnn.graph.edges`).

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
contact (:mod:`physgnn.models.reach`). The network so learns contacts only, and free flight is
exact.
"""

from __future__ import annotations

import torch

from physgnn.graph.edges import PP, PP_CONTACT, PS, PS_CONTACT, PS_MATERIAL, pair_layout
from physgnn.graph.rules import ballistic_velocity

# Scale of the material parameters (restitution, lateral, rolling, spinning friction) as node
# inputs: rolling and spinning coefficients are ~0.01, the others ~0.5.
MATERIAL_SCALE = (1.0, 1.0, 100.0, 100.0)


def pp_contact(graph, state, length_scale, speed_scale) -> torch.Tensor:
    """The :data:`~physgnn.graph.edges.PP_CONTACT` blocks ``[E, 2]``: gap / ℓ and
    ``(v_i − v_j)·n̂_ij`` / σ_v (i the target; a pair of coincident spheres has ``n̂ = 0``)."""
    src, dst = graph.pp_index
    normal, gap = _normal_and_gap(graph, state)
    vel = state.vel[:, 0]
    closing = ((vel[dst] - vel[src]) * normal).sum(1, keepdim=True)
    return PP_CONTACT.join({"gap": gap / length_scale, "normal_speed": closing / speed_scale})


def _normal_and_gap(graph, state) -> tuple[torch.Tensor, torch.Tensor]:
    """``(n̂_ij [E, 3], gap [E, 1])`` of the pp edges: the unit vector from source j to target
    i (0 for coincident spheres) and ``|p_i − p_j| − r_i − r_j``."""
    src, dst = graph.pp_index
    rel, dist = PP.take(graph.pp_attr, "offset"), PP.take(graph.pp_attr, "distance")
    gap = dist - (state.radius[src] + state.radius[dst])[:, None]
    return rel / dist.clamp_min(1e-12), gap


def pair_inputs(
    graph, state, length_scale, speed_scale, history: int, mass_ratio: bool, materials: bool
) -> torch.Tensor:
    """The :func:`~physgnn.graph.edges.pair_layout` blocks ``[E, 5 + 3·history (+1) (+2)]``:
    the pair's *relative* inputs, none of which changes when a
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
    radii = torch.stack([state.radius[dst], state.radius[src]], 1) / length_scale
    parts = {"gap": gap / length_scale, "normal_speed": along / speed_scale}
    parts |= {"tangential_speed": across / speed_scale, "radii": radii}
    parts["velocity_history"] = dv.flatten(1) / speed_scale
    if mass_ratio:
        parts["mass_ratio"] = (state.mass[dst] / (state.mass[dst] + state.mass[src]))[:, None]
    if materials:
        params = state.material_params
        parts["material"] = params[dst, :2] * params[src, :2]
    return pair_layout(history, mass_ratio, materials).join(parts)


def ps_contact(graph, state, length_scale, speed_scale) -> torch.Tensor:
    """The :data:`~physgnn.graph.edges.PS_CONTACT` blocks ``[F, 3]``: clearance ``(h − r)`` / ℓ,
    ``v·n`` / σ_v and the tangential speed / σ_v."""
    ps = graph.ps_attr
    vel, normal, height = (PS.take(ps, name) for name in ("velocity", "normal", "height"))
    clearance = height - state.radius[graph.ps_index[1]][:, None]
    along = (vel * normal).sum(1, keepdim=True)
    across = torch.linalg.vector_norm(vel - along * normal, dim=1, keepdim=True)
    blocks = {"clearance": clearance / length_scale, "normal_speed": along / speed_scale}
    return PS_CONTACT.join(blocks | {"tangential_speed": across / speed_scale})


def ps_material(graph, state) -> torch.Tensor:
    """The :data:`~physgnn.graph.edges.PS_MATERIAL` block ``[F, 2]``: the restitution and
    lateral friction of each ps edge's contact, the sphere's times the plane's (Bullet's
    product rule; planes of a state without ``plane_materials``, and the planes of earlier
    datasets, have restitution and friction 1)."""
    plane, sphere = graph.ps_index
    own = state.material_params[sphere, :2]
    planes = getattr(state, "plane_materials", None)
    return PS_MATERIAL.join({"material": own if planes is None else own * planes[plane, :2]})


def material_features(state) -> torch.Tensor:
    """``[N, 4]``: the material rows scaled by :data:`MATERIAL_SCALE`, by a Python scalar (a
    tensor of the scales would be a host-to-device copy per call)."""
    params = state.material_params
    return torch.stack([params[:, k] * s for k, s in enumerate(MATERIAL_SCALE)], dim=-1)


def free_flight(state) -> tuple[torch.Tensor, torch.Tensor]:
    """``(v_t + g·dt, ω_t)`` ``[N, 3]`` each: the ballistic next velocities (g only in scenes
    with gravity; :func:`~physgnn.graph.rules.ballistic_velocity`)."""
    return ballistic_velocity(state), state.angvel[:, 0]


def gravity_share(stats: dict) -> float:
    """The share ``s`` of ``g·dt`` in a free-flying sphere's mean velocity over a frame, as the
    truth's integrator moves it: semi-implicit Euler at k substeps (``stats["substeps"]``, the
    training data's) gives ``Δp = dt·v_t + g·dt²·(k + 1)/(2k)``; data without substeps (0 or
    absent) the exact parabola, ``s = 1/2``."""
    k = int(stats.get("substeps", 0) or 0)
    return (k + 1) / (2 * k) if k > 0 else 0.5
