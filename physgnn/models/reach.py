"""Which spheres the network decides for: the gravity prior's reach, planes within reach, and
support through contacts (the default model; :mod:`physgnn.models.learned`).

- **In reach** (:func:`contact_reach`): a sphere that may touch something before the next
  frame: a pp edge, an edge to a wall or static plane (the graph's own rule), or the ground
  within the graph's plane rule counting gravity's fall within the frame
  (:meth:`~physgnn.graph.builder.GraphBuilder.touches_plane`: for ``vi``, ``vmax``,
  ``epsilon`` ``h − r ≤ a_i + ε + g·dt²``; ``approach`` counts the fall itself), under the
  ballistic motion or any provisional velocity of an earlier pass. Every
  other sphere flies ballistically: ``v_{t+1} = v_t + g·dt``, ``ω_{t+1} = ω_t`` exactly.
- **Near a plane**: the same, planes only. Only these spheres take a change of their own from
  the network (a plane is external: it may change a sphere's momentum); sphere–sphere changes
  are pair impulses (:mod:`physgnn.models.impulses`).
- **Supported** (:func:`supported`): near a plane, or joined to one through at most
  :data:`SUPPORT_HOPS` pp edges. Only a supported sphere may be put at rest by the rest
  decision, so a group in flight keeps its momentum whatever the network says.
- **The latch** (``recent_contact``, the previous default; off in the default model): also
  every sphere whose last frame was not ballistic, ``|v_t − v_{t−1} − g·dt| > RECENT_TOL``.
  Training noise trips it for most free-flying spheres, and a model's own outputs keep it on
  after a contact, so free flight after a contact became the network's; without it a sphere
  with no contact is ballistic, also right after one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from physgnn.data.state import scene_of_sphere
from physgnn.physics.energy import G
from physgnn.physics.geometry import edge_plane_depth
from physgnn.physics.scene import EFFECT_NAMES, GROUND

GRAVITY = EFFECT_NAMES.index("gravity")
# m/s: a velocity change this far from g·dt within one frame was a contact (ballistic frames
# of the data and of rollouts agree with g·dt to float rounding, about 1e-4 m/s)
RECENT_TOL = 0.01
# pp edges a support chain may follow from a plane (columns and stacks up to this height)
SUPPORT_HOPS = 16


@dataclass
class Reach:
    """``[N]`` bool each: ``spheres`` in reach of a contact, ``planes`` near a plane,
    ``supported`` through contacts by a plane (module doc)."""

    spheres: torch.Tensor
    planes: torch.Tensor
    supported: torch.Tensor


def contact_reach(state, graph, builder, provisional: Sequence = (), latch=False) -> Reach:
    """The :class:`Reach` of ``graph`` (built from ``state`` by ``builder`` with the same
    ``provisional`` velocities); ``latch``: add :func:`recent_contact` to the spheres in
    reach."""
    n = state.pos.shape[0]
    plane, sphere = graph.ps_index
    near = plane_edges_in_reach(state, graph, builder, provisional)
    on_plane = state.pos.new_zeros(n).index_add_(0, sphere, near.to(state.pos.dtype)) > 0
    pp_weight = graph.pp_weight(state.pos)
    if pp_weight is None:
        pp_weight = state.pos.new_ones(graph.pp_index.shape[1])
    linked = state.pos.new_zeros(n).index_add_(0, graph.pp_index[1], pp_weight) > 0
    spheres = on_plane | linked
    if latch:
        spheres = spheres | recent_contact(state)
    return Reach(spheres, on_plane, supported(graph, on_plane, pp_weight))


def plane_edges_in_reach(state, graph, builder, provisional: Sequence = ()) -> torch.Tensor:
    """``[F]`` bool: ps edges whose plane the sphere may touch before the next frame (module
    doc): every wall / static edge the graph kept, the ground by the builder's
    :meth:`~physgnn.graph.builder.GraphBuilder.touches_plane`."""
    plane, sphere = graph.ps_index
    bounded = state.plane_kind[plane] != GROUND
    # the edge features' heights are clipped: the clearance from the geometry itself
    depth = edge_plane_depth(
        state.pos, state.radius, state.planes, state.plane_kind, graph.ps_index
    )
    normal = state.planes[plane, 3:6]
    near = builder.touches_plane(state, sphere, normal, -depth, graph.allowance, provisional)
    near = bounded | near
    if graph.masked:  # a fixed-capacity graph's candidates outside the rules
        near = near & graph.ps_mask
    return near


def supported(graph, on_plane: torch.Tensor, pp_weight: torch.Tensor) -> torch.Tensor:
    """``[N]`` bool: ``on_plane`` spheres and those joined to one through at most
    :data:`SUPPORT_HOPS` pp edges (``pp_weight [E]``: 1 for an edge that counts)."""
    src, dst = graph.pp_index
    if src.shape[0] == 0:
        return on_plane
    held = on_plane.to(pp_weight.dtype)
    for _ in range(SUPPORT_HOPS):
        reached = torch.zeros_like(held).index_add_(0, dst, held[src] * pp_weight)
        held = torch.maximum(held, (reached > 0).to(held.dtype))
    return held > 0


def recent_contact(state) -> torch.Tensor:
    """``[N]`` bool: spheres whose last frame was not ballistic,
    ``|v_t − v_{t−1} − g·dt| > RECENT_TOL`` (all False without a velocity history)."""
    if state.vel.dim() < 3 or state.vel.shape[1] < 2:
        return torch.zeros(state.pos.shape[0], dtype=torch.bool, device=state.pos.device)
    gravity = state.effects[scene_of_sphere(state), GRAVITY].to(state.pos.dtype)
    change = state.vel[:, 0] - state.vel[:, 1]
    change[:, 2] = change[:, 2] + G * state.scene_dt * gravity
    return torch.linalg.vector_norm(change, dim=1) > RECENT_TOL
