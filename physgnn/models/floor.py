"""The plane answers last (``model.contacts.plane_floor``): after the pair impulses, each ps
edge is a one-sided floor, a plane of infinite mass, then the node decoder adds the learned
restitution and friction.

When the ground answers in parallel with the pairs, a landing stack's pair impulses pass the
upper layers' momentum down in the same pass in which the bottom sphere's own plane change is
decided, and the bottom sphere sinks (from a perfect state, 0.28 d in one frame). The floor
takes the velocities after the pair impulses and gravity, and for a ps edge ``e`` (plane s,
sphere i) with contact direction ``d_e`` (the plane's normal ``n_s`` where the centre faces the
plane's inside, else from the closest point of its rim to the centre) and clearance
``c_e = distance − r_i``:

- the frame's move may not cross the plane: ``ū_i·d_e ≥ −max(c_e, 0)/dt`` (the deficit added
  along ``d_e``);
- where it would have (the edge's floor acted), the end velocity may not approach it:
  ``v_i·d_e ≥ 0`` (the engine state, whose end velocity is apart from the move; a
  finite-difference state's velocity is its move);
- with ``bounce`` (``model.contacts.plane_newton``, the engine state), a sphere that arrives in
  free flight then leaves by Newton's law of restitution, in closed form (:func:`free_bounce`):
  the floor's inelastic answer plus the rebound ``e_c·w`` it would have had, so that the
  network's own change is only what the engine does otherwise.

Shapes: ``ps_index [2, F]`` (plane, sphere), ``ps_attr [F, PS.width]`` raw (the
:data:`~physgnn.graph.edges.PS` blocks ``offset`` δ and ``height`` h = δ·n, clipped at the
sphere's reach), velocities ``[N, 3]``. Corrections of several edges of one sphere add up.
"""

from __future__ import annotations

import torch

from physgnn.graph.edges import PS
from physgnn.graph.rules import ballistic_velocity

RIM = 1e-4  # m: a closest point further than this from the foot of the normal is on the rim


def contact_directions(graph, radius: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(d [F, 3], c [F])``: every ps edge's unit contact direction (plane → sphere) and
    clearance (m)."""
    offset, height = PS.take(graph.ps_attr, "offset"), PS.take(graph.ps_attr, "height")
    normal = PS.take(graph.ps_attr, "normal")
    tangential = offset - height * normal
    length = offset.norm(dim=1, keepdim=True)
    rim = tangential.norm(dim=1, keepdim=True) > RIM
    direction = torch.where(rim, offset / length.clamp_min(1e-12), normal)
    distance = torch.where(rim, length, height)[:, 0]
    return direction, distance - radius[graph.ps_index[1]]


def plane_floor(
    state,
    graph,
    mean: torch.Tensor,
    end: torch.Tensor | None = None,
    bounce: bool = False,
    contacts: tuple[torch.Tensor, torch.Tensor] | None = None,
):
    """``(mean, end)`` after the floor of every ps edge (module doc): ``mean [N, 3]`` the
    frame's move ū, ``end [N, 3]`` the end velocity (None: a finite-difference state, only the
    move); ``bounce``: where the floor acted, add :func:`free_bounce`'s rebound; ``contacts``:
    :func:`contact_directions` of the graph, where the caller has them already."""
    direction, clearance, deficit = _deficits(state, graph, mean, contacts)
    sphere = graph.ps_index[1]
    dt = state.scene_dt[sphere]
    mean = mean.index_add(0, sphere, deficit[:, None] * direction)
    if end is None:
        return mean, None
    acted = (deficit > 0).to(end.dtype)
    approach = torch.relu(-(end[sphere] * direction).sum(1)) * acted
    if bounce:
        lift, speed = free_bounce(state, graph, direction, clearance)
        mean = mean.index_add(0, sphere, (acted * lift / dt)[:, None] * direction)
        approach = approach + acted * speed
    return mean, end.index_add(0, sphere, approach[:, None] * direction)


def pressed(state, graph, mean: torch.Tensor, contacts=None) -> torch.Tensor:
    """``[N]`` bool: the spheres whose move ``mean [N, 3]`` some plane's floor stops (the
    spheres a plane touches in the frame: resting, rolling, landing)."""
    deficit = _deficits(state, graph, mean, contacts)[2]
    acted = (deficit > 0).to(mean.dtype)
    return mean.new_zeros(mean.shape[0]).index_add_(0, graph.ps_index[1], acted) > 0


def _deficits(state, graph, mean, contacts=None):
    """``(d [F, 3], c [F], deficit [F])``: each ps edge's contact direction and clearance and
    the speed along ``d`` that the floor adds to ``mean`` (0 where the move does not cross)."""
    direction, clearance = contacts or contact_directions(graph, state.radius)
    sphere = graph.ps_index[1]
    limit = -clearance.clamp_min(0) / state.scene_dt[sphere]
    deficit = torch.relu(limit - (mean[sphere] * direction).sum(1))
    weight = graph.ps_weight(clearance)
    return direction, clearance, deficit if weight is None else deficit * weight


def free_bounce(state, graph, direction, clearance) -> tuple[torch.Tensor, torch.Tensor]:
    """``(lift [F], speed [F])``: for every ps edge, where its sphere ends a frame that it
    starts in free flight and in which it meets the plane and rebounds by Newton's law, above
    the plane (m) and along ``d_e`` (m/s); zeros where it does not rise clear by the frame's end.

    Along ``d_e`` the sphere starts at clearance ``c = max(c_e, 0)`` with speed
    ``u = v_t·d_e`` (its engine velocity, before any pair impulse: a push passed down a
    resting stack is a force, not an arrival) under gravity's ``a = g·d_e``. It meets the
    plane at ``τ = 2c / (w − u)`` with speed ``w = √(u² − 2ac)``, leaves with ``e_c·w``
    (``e_c = e_i·e_s``, the engine's combination of the sphere's and the plane's
    restitution) and after the rest of the frame ``ρ = dt − τ`` is at
    ``e_c·w·ρ + a·ρ²/2`` with speed ``e_c·w + a·ρ``. A rebound that would land again within
    the frame counts as none (the floor's inelastic answer)."""
    plane, sphere = graph.ps_index
    dt = state.scene_dt[sphere]
    start = state.vel[:, 0] if state.vel.dim() == 3 else state.vel
    u = (start[sphere] * direction).sum(1)
    fall = (ballistic_velocity(state) - start)[sphere]  # g·dt where gravity is on
    a = (fall * direction).sum(1) / dt
    c = clearance.clamp_min(0)
    w = torch.sqrt(torch.relu(u.square() - 2 * a * c))
    meets = (w - u) > 1e-9
    tau = torch.where(meets, 2 * c / (w - u).clamp_min(1e-9), dt)
    rest = torch.relu(dt - tau)
    restitution = state.material_params[sphere, 0] * state.plane_materials[plane, 0]
    rebound = restitution * w
    lift = rebound * rest + 0.5 * a * rest.square()
    clear = (meets & (lift > 0)).to(lift.dtype)
    return lift * clear, (rebound + a * rest) * clear
