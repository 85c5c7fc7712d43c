"""Sphere–sphere (pp) and surface–sphere (ps) edges with their features, rebuilt every step.

Connectivity, with ``gap_ij = |p_i − p_j| − r_i − r_j`` and a per-sphere motion allowance ``a_i``:

- ``approach`` (the default model's): by the pair's *relative* motion. With
  ``n̂_ij = (p_i − p_j)/|p_i − p_j|`` and the closing speed ``c_ij = max(0, −(v_i − v_j)·n̂_ij)``,
  pp edge iff ``gap_ij ≤ factor · c_ij · dt + ε`` (ε a thin shell that keeps resting contacts
  linked). Spheres moving as one (``v_i = v_j``) are never linked unless they touch: a block in
  free flight has no pp edge. Superset property: with constant relative velocity ``w`` over
  the frame, ``|d + wτ| ≥ (d + wτ)·n̂ = |d| − τ·(−w·n̂)``, so no pair can touch by ``dt`` that
  the rule leaves out (factor ≥ 1); gravity cancels in ``w`` when both spheres fly (not when
  one is supported: "Contacts within the frame" below). A bounded plane is linked when
  its rectangle's clearance ``|δ| − r_i ≤ factor · max(0, −v̂_i·δ̂) · dt + ε``, with the
  ballistic next velocity ``v̂_i = v_i + g·dt`` (a plane is static, so gravity does close the
  gap) and ``δ̂`` the unit offset from the rectangle's closest point (a supporting half-space
  bounds the distance alike). ``a_i = factor · |v̂_i| · dt`` sizes the search and the clip.
- ``epsilon``: ``a_i = 0``
- ``vmax``:    ``a_i = factor · V_max · dt``, V_max the largest speed in the sphere's scene
- ``vi``:      ``a_i = factor · |v_i| · dt``

For the last three: pp edge iff ``gap_ij ≤ a_i + a_j + ε``; ps edge to a bounded non-ground
plane iff (distance from the centre to the closest point of the rectangle) ``− r_i ≤ a_i + ε``.
Every rule: the centre is not more than ``r_i`` behind a bounded plane (planes are one-sided: a
sphere wholly behind one has tunnelled and feels nothing); plus one edge from every sphere's
ground plane. The rules are evaluated in float64 (boundary included); the features are in the
input dtype and in raw physical units.

**Features see no absolute position.** A ps edge (the blocks of
:data:`~physgnn.graph.edges.PS`) carries the offset ``δ`` from the closest
point of the plane (the rectangle for bounded planes, the infinite plane for the ground) to
the sphere's centre, and the signed height ``h = δ·n_s``, both clipped at the sphere's reach
``ρ_i = r_i + a_i + ε`` plus ``clip_margin``: a sphere farther than the reach cannot touch the
plane before the next frame, and the clipped ground edge of a sphere in free flight is the
same at 10, 100 or 1 000 m (so gravity does not grow with altitude).

**Contacts within the frame.** The superset property above holds under the rule's own
assumption, each sphere moving with its ballistic velocity for the whole frame. It fails when a
sphere's motion changes within the frame: a neighbour stopped by the ground (a block's bottom
layer lands, a ball hits a resting row) or a sphere that rests while a falling one comes down on
it (gravity does not cancel in that pair). So a build also takes the provisional next
velocities of earlier passes of a simulator (``provisional``): a candidate is kept when the rules
accept it under the ballistic motion *or* under any provisional one (the union, so a graph only
grows from pass to pass), and the allowance is the largest of them. Under each velocity the
superset property holds as above (tested against brute force); a simulator passes again while
a rebuild adds edges (:class:`~physgnn.models.learned.LearnedSimulator`, ``contact_passes``).
A rebuild with one more velocity (:meth:`GraphBuilder.extend`) reuses the last build's
candidates and masks where that velocity widens no allowance (on the CPU: 1.11–1.14× faster
frames of the default model, the same graph edge for edge).

Effects (``state.effects``): no pp edges without ``sphere_contact``; no wall/static edges
without ``surface_contact``; the ground edge exists when ``gravity`` or ``surface_contact``.

**Counted or fixed capacity.** By default a build keeps the candidates the rules accept,
given their count: one read-back per build (:func:`~physgnn.graph.candidates.compact`), edges
of exactly the graph's size. With ``fixed_capacity=True`` it reads nothing back: the graph
holds every candidate of the batch's layout (a size the host knows) with masks of the edges
the rules accept (``pp_mask``, ``ps_mask``), and every consumer weighs an edge by its mask;
the network sees the masked edges as ghost edges
(:meth:`~physgnn.graph.edges.Graph.network_inputs`), padded to capacity buckets
(:mod:`physgnn.nn.padding`), so its shapes follow the layout's bucket only, as a captured step
needs. It costs more arithmetic (every same-scene pair, where the counted graph has the few
in reach), so it is meant for batches of small scenes on a GPU. A batch whose candidates pass
the ``ALL_PAIRS_*`` limits (a radius search reads sizes back anyway) is built counted.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from physgnn.data.state import host_sizes, scene_of_sphere
from physgnn.graph.candidates import compact, scene_counts, scene_pairs, scene_plane_pairs
from physgnn.graph.edges import Graph, paired_edges, ps_features
from physgnn.graph.neighbors import BACKENDS, radius_pairs, resolve_backend
from physgnn.physics.energy import G
from physgnn.physics.geometry import rectangle_offset
from physgnn.physics.scene import EFFECT_NAMES, GROUND

CONNECTIVITIES = ("approach", "epsilon", "vmax", "vi")
_GRAVITY = EFFECT_NAMES.index("gravity")
_SPHERE_CONTACT = EFFECT_NAMES.index("sphere_contact")
_SURFACE_CONTACT = EFFECT_NAMES.index("surface_contact")
# pp candidates: all pairs of each scene (no read-back) up to these limits, then a radius search;
# with the CPU's k-d tree, where a read-back costs nothing, the search from 8 pairs per sphere.
ALL_PAIRS_MAX, ALL_PAIRS_PER_SPHERE, CPU_PAIRS_PER_SPHERE = 1 << 18, 64, 8


@dataclass(frozen=True)
class Basis:
    """What a build compacts its graph from: the allowance ``[N]`` (float64), the candidates
    ``(src [P], dst [P], plane [Q], sphere [Q])``, the rules' masks ``([P], [Q])`` under every
    velocity so far, the ps offsets ``[Q, 3]`` and whether the pp candidates are the layout's
    (:meth:`GraphBuilder.layout_candidates`)."""

    allowance: torch.Tensor
    candidates: tuple[torch.Tensor, ...]
    masks: tuple[torch.Tensor, torch.Tensor]
    offset: torch.Tensor
    layout: bool


class GraphBuilder:
    """Builds a :class:`Graph` from a ``SceneState`` (one scene or a PyG ``Batch`` of them).

    ``epsilon`` is a length in metres; ``factor`` scales the velocity terms; ``backend`` is
    the :func:`physgnn.graph.neighbors.radius_pairs` backend. ``clip_margin`` (metres) moves
    the clip of the ps features beyond the reach, to ``ρ_i + clip_margin``: with 0, a sphere at
    rest on the ground (height r) and one at rest high above it (height clipped at r + ε) look
    almost alike to the network, though only the second falls. The defaults are the default
    model's graph (``conf/model/baseline.yaml``, ``graph``).
    """

    def __init__(
        self,
        connectivity: str = "approach",
        epsilon: float = 0.01,
        factor: float = 1.0,
        backend: str = "auto",
        clip_margin: float = 1.0,
        fixed_capacity: bool = False,
    ):
        if connectivity not in CONNECTIVITIES:
            raise ValueError(
                f"unknown connectivity '{connectivity}'; choose one of {list(CONNECTIVITIES)}"
            )
        for name, value in (("epsilon", epsilon), ("factor", factor), ("clip_margin", clip_margin)):
            if not 0 <= float(value) < float("inf"):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if backend not in BACKENDS:
            raise ValueError(
                f"unknown neighbour backend '{backend}'; choose one of {list(BACKENDS)}"
            )
        self.connectivity = connectivity
        self.epsilon = float(epsilon)
        self.factor = float(factor)
        self.clip_margin = float(clip_margin)
        self.backend = backend
        self.fixed_capacity = bool(fixed_capacity)

    def __call__(self, state, provisional: Sequence[torch.Tensor] = ()) -> Graph:
        """The graph of ``state``; ``provisional``: next velocities ``[N, 3]`` of earlier
        passes (module doc, "Contacts within the frame"): a candidate is kept when the rules
        accept it under the state's own motion or under any of them."""
        return self.build(state, provisional)[0]

    def build(self, state, provisional: Sequence[torch.Tensor] = ()) -> tuple[Graph, Basis]:
        """:meth:`__call__`'s graph and the :class:`Basis` it was compacted from, which
        :meth:`extend` reuses."""
        batch, (spheres, planes) = scene_of_sphere(state), host_sizes(state)
        velocity = self.rule_velocity(state)  # once per build: the rules and the clip share it
        allowance = self.allowance(state, velocity=velocity)
        for vel in provisional:
            allowance = torch.maximum(allowance, self.allowance(state, velocity=vel))
        counts = scene_counts(batch, len(spheres))  # both kinds of candidate need them
        layout = self.layout_candidates(state, spheres)
        src, dst = self._pair_candidates(state, batch, allowance, spheres, counts, layout)
        plane, sphere = scene_plane_pairs(spheres, planes, state.plane_batch.long(), counts)
        pp_mask, ps_mask, offset = self.rules(state, velocity, allowance, src, dst, plane, sphere)
        for vel in provisional:
            more = self.rules(state, vel, allowance, src, dst, plane, sphere, vel)
            pp_mask, ps_mask = pp_mask | more[0], ps_mask | more[1]
        basis = Basis(allowance, (src, dst, plane, sphere), (pp_mask, ps_mask), offset, layout)
        return self._compacted(state, basis), basis

    def extend(self, state, basis: Basis, provisional: Sequence[torch.Tensor]) -> tuple:
        """:meth:`build` with ``provisional``, given ``basis``, the build's with all of them
        but the last: the same graph and basis. Where a read-back costs nothing (the CPU's
        k-d tree) and the last velocity leaves every allowance as it was, the candidates and
        the earlier velocities' masks are the basis's and only the last velocity's rules run;
        else (a GPU would wait to ask) a whole build."""
        if self.fixed_capacity or resolve_backend(self.backend, state.pos) != "kdtree":
            return self.build(state, provisional)
        vel = provisional[-1]
        allowance = torch.maximum(basis.allowance, self.allowance(state, velocity=vel))
        if not torch.equal(allowance, basis.allowance):  # a wider reach: other candidates
            return self.build(state, provisional)
        pp_mask, ps_mask, _ = self.rules(state, vel, allowance, *basis.candidates, vel)
        basis = dataclasses.replace(
            basis, masks=(basis.masks[0] | pp_mask, basis.masks[1] | ps_mask)
        )
        return self._compacted(state, basis), basis

    def _compacted(self, state, basis: Basis) -> Graph:
        """The graph of the candidates ``basis`` accepts (module doc, "Counted or fixed
        capacity")."""
        (src, dst, plane, sphere), (pp_mask, ps_mask) = basis.candidates, basis.masks
        if self.fixed_capacity and basis.layout:  # every candidate, its mask on both halves
            pp_keep, keep, masks = slice(None), slice(None), (pp_mask.repeat(2), ps_mask)
        else:
            n_pp, n_ps = torch.stack([pp_mask.sum(), ps_mask.sum()]).tolist()  # the one read-back
            pp_keep, keep, masks = compact(pp_mask, n_pp), compact(ps_mask, n_ps), (None, None)
        pp_index, pp_attr = paired_edges(state.pos, src[pp_keep], dst[pp_keep])
        ps_index = torch.stack([plane[keep], sphere[keep]])
        if checks_on():
            _check_ground(state, scene_of_sphere(state))
        clip = self.reach(state, basis.allowance) + self.clip_margin
        ps_attr = ps_features(state, ps_index, basis.offset[keep], clip)  # the PS blocks
        return Graph(pp_index, pp_attr, ps_index, ps_attr, basis.allowance, *masks)

    def rules(
        self, state, velocity, allowance, src, dst, plane, sphere, pair_velocity=None
    ) -> tuple:
        """``(pp mask [P], ps mask [Q], offsets [Q, 3] float64)`` of the candidates: the module
        doc's rules, given :meth:`rule_velocity` (or a pass's provisional velocity) and
        :meth:`allowance`; ``pair_velocity [N, 3]``: what the pp rule moves spheres with
        (None: ``v_t``). Reads nothing back: a compiled simulator compiles it
        (:mod:`physgnn.models.capture`)."""
        batch = scene_of_sphere(state)
        on = state.effects[batch[src], _SPHERE_CONTACT]  # scenes with sphere contact
        pp_mask = on & self.pair_within_reach(state, src, dst, allowance, pair_velocity)
        ps_mask, offset = self._ps_rule(state, batch, allowance, plane, sphere, velocity)
        return pp_mask, ps_mask, offset

    def layout_candidates(self, state, spheres: tuple[int, ...]) -> bool:
        """True when the pp candidates are every same-scene pair of the layout (module doc),
        not a radius search's."""
        total = sum(c * (c - 1) // 2 for c in spheres)
        return total <= self._all_pairs_limit(state)

    def _all_pairs_limit(self, state) -> int:
        n = state.pos.shape[0]
        if resolve_backend(self.backend, state.pos) == "kdtree" and not self.fixed_capacity:
            return CPU_PAIRS_PER_SPHERE * n
        return max(ALL_PAIRS_MAX, ALL_PAIRS_PER_SPHERE * n)

    def rule_velocity(self, state) -> torch.Tensor:
        """``[N, 3]``: what the rules move spheres with: ``v_t + g·dt`` (approach), else ``v_t``."""
        return ballistic_velocity(state) if self.connectivity == "approach" else _velocity(state)

    def allowance(self, state, moving=None, velocity=None) -> torch.Tensor:
        """Motion allowance ``a_i`` of every sphere, float64 ``[N]``; ``moving [N]`` (bool):
        only these spheres move, the others count with speed 0 (sleeping spheres);
        ``velocity [N, 3]``: :meth:`rule_velocity` where the caller has it."""
        batch = scene_of_sphere(state)
        vel = self.rule_velocity(state) if velocity is None else velocity
        speed = vel.to(torch.float64).norm(dim=-1)
        if self.connectivity == "epsilon":
            return torch.zeros_like(speed)
        if moving is not None:
            speed = torch.where(moving, speed, 0.0)
        if self.connectivity == "vmax":
            vmax = speed.new_zeros(state.dt.shape[0]).scatter_reduce(0, batch, speed, "amax")
            speed = vmax[batch]
        return self.factor * speed * state.dt.to(torch.float64)[batch]

    def pair_within_reach(self, state, i, j, allowance: torch.Tensor, velocity=None):
        """``[P]`` bool: the pp rule (module doc; ``gap_ij ≤ a_i + a_j + ε`` but for
        ``approach``) of same-scene pairs ``(i, j)``, float64; ``approach`` moves the spheres
        with ``velocity [N, 3]`` (None: ``v_t``; a common gravity cancels in the pair)."""
        batch = scene_of_sphere(state)
        p, r = state.pos.to(torch.float64), state.radius.to(torch.float64)
        rel = p[i] - p[j]
        dist = rel.norm(dim=-1)
        gap = dist - r[i] - r[j]
        if self.connectivity == "approach":
            vel = (_velocity(state) if velocity is None else velocity).to(torch.float64)
            along = ((vel[i] - vel[j]) * rel).sum(-1) / dist.clamp_min(1e-300)
            limit = self._closing_limit(along, state.dt.to(torch.float64)[batch[i]])
        else:
            limit = allowance[i] + allowance[j] + self.epsilon
        return (batch[i] == batch[j]) & (gap <= limit)

    def plane_within_reach(
        self, state, sphere, normal, clearance, allowance, velocity=None, fall=None
    ) -> torch.Tensor:
        """``[Q]`` bool: a plane at ``clearance [Q]`` (float64, from the sphere's surface along
        the unit direction ``normal [Q, 3]`` pointing from the plane to the sphere) can be
        reached by ``sphere [Q]`` before the next frame: ``approach``'s
        ``clearance ≤ factor · max(0, −v̂·n) · dt + ε``, else ``clearance ≤ a_i + ε`` (plus
        ``fall [Q]`` where given: :meth:`touches_plane`); ``velocity [N, 3]``:
        :meth:`rule_velocity` where the caller has it."""
        if self.connectivity != "approach":
            limit = allowance[sphere] + self.epsilon
            return clearance <= (limit if fall is None else limit + fall)
        vel = self.rule_velocity(state) if velocity is None else velocity
        vel = vel.to(torch.float64)[sphere]
        along = (vel * normal.to(torch.float64)).sum(-1)
        dt = state.dt.to(torch.float64)[scene_of_sphere(state)[sphere]]
        return clearance <= self._closing_limit(along, dt)

    def touches_plane(
        self, state, sphere, normal, clearance, allowance, provisional: Sequence = ()
    ) -> torch.Tensor:
        """``[Q]`` bool: :meth:`plane_within_reach` counting gravity's fall within the frame,
        under the rule's own motion or any ``provisional`` velocity (the union, as a build
        keeps edges): ``approach`` moves spheres by ``v̂ = v + g·dt``, which counts the fall,
        and reads each velocity; the other rules add the fall ``g·dt²`` to ``a_i + ε`` (their
        allowance already holds the provisional velocities). The gravity prior's plane reach
        (:mod:`physgnn.models.reach`)."""
        args = state, sphere, normal, clearance, allowance
        if self.connectivity != "approach":
            dt = state.scene_dt[sphere]
            return self.plane_within_reach(*args, fall=G * dt * dt)
        near = self.plane_within_reach(*args)
        for vel in provisional:
            near = near | self.plane_within_reach(*args, vel)
        return near

    def _closing_limit(self, along: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
        """``approach``'s limit ``factor · max(0, −along) · dt + ε`` of a gap or clearance, with
        ``along`` the velocity along the direction from the contact to the sphere (float64)."""
        return self.factor * torch.relu(-along) * dt + self.epsilon

    def _pair_candidates(self, state, batch, allowance, spheres, counts, layout) -> tuple:
        """Candidate pairs ``(i, j)``, ``i < j``, sorted: all pairs of each scene when ``layout``
        (:meth:`layout_candidates`), else a radius search (reads sizes back,
        :func:`~physgnn.graph.neighbors.radius_pairs`); the same edges either way."""
        if layout:
            return scene_pairs(spheres, batch, counts)
        radius = state.radius.to(torch.float64)
        reach = 2 * float(radius.max()) + 2 * float(allowance.max()) + self.epsilon
        pairs = radius_pairs(state.pos, reach * (1 + 1e-9), batch, self.backend)
        return pairs[0], pairs[1]

    def reach(self, state, allowance: torch.Tensor) -> torch.Tensor:
        """``ρ_i = r_i + a_i + ε``, float64 ``[N]``: the farthest plane a sphere may touch."""
        return state.radius.to(torch.float64) + allowance + self.epsilon

    def _ps_rule(self, state, batch, allowance, plane, sphere, vel) -> tuple[torch.Tensor, ...]:
        """``([Q] bool, offsets [Q, 3] float64)`` for (plane, sphere) candidates of one scene
        (the offsets from each rectangle, kept for the edge features): the ground of a scene with
        gravity or surface contact; a wall or static plane of a scene with surface contact
        whose rectangle is in reach (:meth:`plane_within_reach` with ``vel``, the rule's
        velocity) and which the centre is not more than ``r_i`` behind (planes are one-sided)."""
        effects = state.effects[batch[sphere]]
        ground = state.plane_kind[plane] == GROUND
        offset = rectangle_offset(state.pos[sphere], state.planes[plane])
        radius = state.radius.to(torch.float64)[sphere]
        height = (offset * state.planes[plane, 3:6].to(torch.float64)).sum(-1)
        dist = offset.norm(dim=-1, keepdim=True)
        direction = offset / dist.clamp_min(1e-300)
        clearance = dist[:, 0] - radius
        near = self.plane_within_reach(state, sphere, direction, clearance, allowance, vel)
        bounded = ~ground & effects[:, _SURFACE_CONTACT] & near & (height > -radius)
        keep = (ground & (effects[:, _GRAVITY] | effects[:, _SURFACE_CONTACT])) | bounded
        return keep, offset


def build_graph(state, cfg: Mapping) -> Graph:
    """``GraphBuilder(**cfg)(state)``: cfg holds the builder's arguments (config keys)."""
    return GraphBuilder(**dict(cfg))(state)


def ballistic_velocity(state) -> torch.Tensor:
    """``v_t + g·dt`` ``[N, 3]``: the next velocity in free flight (g only in scenes with
    gravity)."""
    gravity = state.effects[scene_of_sphere(state), _GRAVITY].to(state.pos.dtype)
    vel = _velocity(state).clone()
    vel[:, 2] = vel[:, 2] - G * state.scene_dt * gravity
    return vel


def _velocity(state) -> torch.Tensor:
    """Current velocity ``v_t``, ``[N, 3]`` (``vel`` is ``[N, H+1, 3]``, latest first)."""
    return state.vel[:, 0] if state.vel.dim() == 3 else state.vel


def checks_on() -> bool:
    """Checks that read values back to the host (``PHYSGNN_CHECKS=1``; off by default, so
    that a GPU step never waits for them)."""
    return os.environ.get("PHYSGNN_CHECKS", "") == "1"


def _check_ground(state, batch) -> None:
    """Every scene with a sphere that needs a ground edge has exactly one ground plane."""
    effects = state.effects
    grounds = (state.plane_kind == GROUND).long()
    per_scene = torch.zeros_like(effects[:, 0], dtype=torch.long)
    per_scene.scatter_add_(0, state.plane_batch.long(), grounds)
    needed = torch.zeros_like(effects[:, 0]).index_fill_(0, batch, True)
    needed &= effects[:, _GRAVITY] | effects[:, _SURFACE_CONTACT]
    bad = (needed & (per_scene != 1)).nonzero().flatten().tolist()
    if bad:
        raise ValueError(f"scene {bad[0]} of the batch must have exactly one ground plane (kind 0)")
