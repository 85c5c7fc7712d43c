"""Sphere–sphere (pp) and surface–sphere (ps) edges with their features, rebuilt every step.

Connectivity, with ``gap_ij = |p_i − p_j| − r_i − r_j`` and a per-sphere
motion allowance ``a_i``:

- ``epsilon``: ``a_i = 0``
- ``vmax``:    ``a_i = factor · V_max · dt``, V_max the largest speed in the sphere's scene
- ``vi``:      ``a_i = factor · |v_i| · dt``

pp edge iff ``gap_ij ≤ a_i + a_j + ε``; ps edge to a bounded non-ground plane iff
(distance from the centre to the closest point of the rectangle) ``− r_i ≤ a_i + ε`` and the
centre is not more than ``r_i`` behind the plane (planes are one-sided: a sphere wholly behind
one has tunnelled and feels nothing); plus one edge from every sphere's ground plane. The
rules are evaluated in float64 (boundary included); the features are in the input dtype and
in raw physical units.

**Features see no absolute position.** A ps edge carries the offset ``δ`` from the closest
point of the plane (the rectangle for bounded planes, the infinite plane for the ground) to
the sphere's centre, and the signed height ``h = δ·n_s``, both clipped at the sphere's reach
``ρ_i = r_i + a_i + ε`` plus ``clip_margin``: a sphere farther than the reach cannot touch the
plane before the next frame, and the clipped ground edge of a sphere in free flight is the
same at 10, 100 or 1 000 m (so gravity does not grow with altitude).

Effects (``state.effects``): no pp edges without ``sphere_contact``; no wall/static edges
without ``surface_contact``; the ground edge exists when ``gravity`` or ``surface_contact``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import torch

from physgnn.data.state import scene_of_sphere
from physgnn.graph.neighbors import BACKENDS, radius_pairs
from physgnn.physics.geometry import rectangle_offset
from physgnn.physics.scene import EFFECT_NAMES, GROUND

CONNECTIVITIES = ("epsilon", "vmax", "vi")
_GRAVITY = EFFECT_NAMES.index("gravity")
_SPHERE_CONTACT = EFFECT_NAMES.index("sphere_contact")
_SURFACE_CONTACT = EFFECT_NAMES.index("surface_contact")


@dataclass
class Graph:
    """Edges of a batch of scenes (E pp edges, F ps edges; PyG flow source → target).

    - ``pp_index [2, E]``: row 0 source j, row 1 target i, *paired layout*: columns
      ``[0, E/2)`` hold each unordered pair once (source < target, sorted), columns
      ``[E/2, E)`` the same pairs reversed, so the reverse of edge e is edge ``e + E/2``.
    - ``pp_attr [E, 4]``: ``[p_i − p_j, |p_i − p_j|]`` (i the target).
    - ``ps_index [2, F]``: row 0 plane index into ``state.planes``, row 1 sphere index,
      sorted by (plane, sphere).
    - ``ps_attr [F, 10]``: ``[v_i, n_s, clip(δ_is), clip(h_is)]``: ``δ_is`` the offset from the
      closest point of plane s to sphere i, ``h_is = δ_is·n_s`` (signed), clipped at ``ρ_i``.
    - ``allowance [N]`` (float64): the motion allowance ``a_i`` the edges were chosen with.
    """

    pp_index: torch.Tensor
    pp_attr: torch.Tensor
    ps_index: torch.Tensor
    ps_attr: torch.Tensor
    allowance: torch.Tensor

    @property
    def num_pairs(self) -> int:
        """Number of unordered sphere pairs (``E / 2``)."""
        return self.pp_index.shape[1] // 2


class GraphBuilder:
    """Builds a :class:`Graph` from a ``SceneState`` (one scene or a PyG ``Batch`` of them).

    ``epsilon`` is a length in metres; ``factor`` scales the velocity terms; ``backend`` is
    the :func:`physgnn.graph.neighbors.radius_pairs` backend. ``clip_margin`` (metres) moves
    the clip of the ps features beyond the reach, to ``ρ_i + clip_margin``: with 0, a sphere at
    rest on the ground (height r) and one at rest high above it (height clipped at r + ε) look
    almost alike to the network, though only the second falls.
    """

    def __init__(
        self,
        connectivity: str = "vi",
        epsilon: float = 0.01,
        factor: float = 1.0,
        backend: str = "auto",
        clip_margin: float = 0.0,
    ):
        if connectivity not in CONNECTIVITIES:
            raise ValueError(
                f"unknown connectivity '{connectivity}'; choose one of {list(CONNECTIVITIES)}"
            )
        if not 0 <= float(epsilon) < float("inf"):
            raise ValueError(f"epsilon must be finite and >= 0, got {epsilon}")
        if not 0 <= float(factor) < float("inf"):
            raise ValueError(f"factor must be finite and >= 0, got {factor}")
        if not 0 <= float(clip_margin) < float("inf"):
            raise ValueError(f"clip_margin must be finite and >= 0, got {clip_margin}")
        if backend not in BACKENDS:
            raise ValueError(
                f"unknown neighbour backend '{backend}'; choose one of {list(BACKENDS)}"
            )
        self.connectivity = connectivity
        self.epsilon = float(epsilon)
        self.factor = float(factor)
        self.clip_margin = float(clip_margin)
        self.backend = backend

    def __call__(self, state) -> Graph:
        batch = scene_of_sphere(state)
        allowance = self.allowance(state)
        pp_index, pp_attr = self._pp_edges(state, batch, allowance)
        ps_index, ps_attr = self._ps_edges(state, batch, allowance)
        return Graph(pp_index, pp_attr, ps_index, ps_attr, allowance)

    def allowance(self, state, moving: torch.Tensor | None = None) -> torch.Tensor:
        """Motion allowance ``a_i`` of every sphere, float64 ``[N]``; ``moving [N]`` (bool):
        only these spheres move, the others count with speed 0 (sleeping spheres)."""
        batch = scene_of_sphere(state)
        speed = _velocity(state).to(torch.float64).norm(dim=-1)
        if self.connectivity == "epsilon":
            return torch.zeros_like(speed)
        if moving is not None:
            speed = torch.where(moving, speed, 0.0)
        if self.connectivity == "vmax":
            vmax = speed.new_zeros(state.dt.shape[0]).scatter_reduce(0, batch, speed, "amax")
            speed = vmax[batch]
        return self.factor * speed * state.dt.to(torch.float64)[batch]

    def pair_within_reach(self, state, i, j, allowance: torch.Tensor) -> torch.Tensor:
        """``[P]`` bool: the pp rule ``gap_ij ≤ a_i + a_j + ε`` (same scene) for pairs
        ``(i, j)``, float64."""
        batch = scene_of_sphere(state)
        p, r = state.pos.to(torch.float64), state.radius.to(torch.float64)
        gap = (p[i] - p[j]).norm(dim=-1) - r[i] - r[j]
        return (batch[i] == batch[j]) & (gap <= allowance[i] + allowance[j] + self.epsilon)

    def _pp_edges(self, state, batch, allowance) -> tuple[torch.Tensor, torch.Tensor]:
        pos = state.pos
        on = state.effects[:, _SPHERE_CONTACT][batch]
        nodes = torch.nonzero(on).flatten()
        if nodes.numel() < 2:
            return _empty_index(pos.device), pos.new_zeros(0, 4)
        radius = state.radius.to(torch.float64)
        reach = 2 * float(radius[nodes].max()) + 2 * float(allowance[nodes].max()) + self.epsilon
        local = radius_pairs(pos[nodes], reach * (1 + 1e-9), batch[nodes], self.backend)
        src, dst = nodes[local[0]], nodes[local[1]]
        keep = self.pair_within_reach(state, src, dst, allowance)
        src, dst = src[keep], dst[keep]
        rel = pos[dst] - pos[src]
        attr = torch.cat([rel, torch.linalg.vector_norm(rel, dim=-1, keepdim=True)], dim=-1)
        index = torch.cat([torch.stack([src, dst]), torch.stack([dst, src])], dim=1)
        rev = torch.cat([-attr[:, :3], attr[:, 3:]], dim=-1)
        return index, torch.cat([attr, rev], dim=0)

    def reach(self, state, allowance: torch.Tensor) -> torch.Tensor:
        """``ρ_i = r_i + a_i + ε``, float64 ``[N]``: the farthest plane a sphere may touch."""
        return state.radius.to(torch.float64) + allowance + self.epsilon

    def _ps_edges(self, state, batch, allowance) -> tuple[torch.Tensor, torch.Tensor]:
        ground = _ground_edges(state, batch)
        bounded = self._bounded_plane_edges(state, batch, allowance)
        n = state.pos.shape[0]
        key = torch.cat([ground[0] * n + ground[1], bounded[0] * n + bounded[1]])
        key = torch.sort(key).values
        index = torch.stack([key // max(n, 1), key % max(n, 1)])
        clip = self.reach(state, allowance) + self.clip_margin
        return index, _ps_attr(state, index, clip)

    def _bounded_plane_edges(self, state, batch, allowance) -> torch.Tensor:
        """Edges from walls/static planes to spheres within reach, ``[2, F']``."""
        planes, device = state.planes, state.pos.device
        plane_batch = state.plane_batch.long()
        active = (state.plane_kind != GROUND) & state.effects[plane_batch, _SURFACE_CONTACT]
        plane_ids = torch.nonzero(active).flatten()
        if plane_ids.numel() == 0 or state.pos.shape[0] == 0:
            return _empty_index(device)
        # Every (plane, sphere of the plane's scene) candidate, without a loop over planes.
        order = torch.argsort(batch, stable=True)
        counts = torch.bincount(batch, minlength=state.dt.shape[0])
        first = torch.cumsum(counts, 0) - counts
        per_plane = counts[plane_batch[plane_ids]]
        plane = torch.repeat_interleave(plane_ids, per_plane)
        offset = torch.arange(plane.numel(), device=device)
        offset = offset - torch.repeat_interleave(torch.cumsum(per_plane, 0) - per_plane, per_plane)
        sphere = order[first[plane_batch[plane]] + offset]
        offset = rectangle_offset(state.pos[sphere], planes[plane])
        radius = state.radius.to(torch.float64)[sphere]
        height = (offset * planes[plane, 3:6].to(torch.float64)).sum(-1)
        near = offset.norm(dim=-1) - radius <= allowance[sphere] + self.epsilon
        keep = near & (height > -radius)
        return torch.stack([plane[keep], sphere[keep]])


def build_graph(state, cfg: Mapping) -> Graph:
    """``GraphBuilder(**cfg)(state)``: cfg holds the builder's arguments (config keys)."""
    return GraphBuilder(**dict(cfg))(state)


def _velocity(state) -> torch.Tensor:
    """Current velocity ``v_t``, ``[N, 3]`` (``vel`` is ``[N, H+1, 3]``, latest first)."""
    return state.vel[:, 0] if state.vel.dim() == 3 else state.vel


def _empty_index(device) -> torch.Tensor:
    return torch.empty(2, 0, dtype=torch.long, device=device)


def _ground_edges(state, batch) -> torch.Tensor:
    """One edge from its scene's ground to every sphere of a scene with gravity or surfaces."""
    effects = state.effects
    on = (effects[:, _GRAVITY] | effects[:, _SURFACE_CONTACT])[batch]
    spheres = torch.nonzero(on).flatten()
    if spheres.numel() == 0:
        return _empty_index(state.pos.device)
    grounds = torch.nonzero(state.plane_kind == GROUND).flatten()
    scene_of_ground = state.plane_batch.long()[grounds]
    per_scene = torch.bincount(scene_of_ground, minlength=effects.shape[0])
    needed = torch.unique(batch[spheres])
    if bool((per_scene[needed] != 1).any()):
        bad = int(needed[per_scene[needed] != 1][0])
        raise ValueError(f"scene {bad} of the batch must have exactly one ground plane (kind 0)")
    ground_of = torch.full_like(per_scene, -1)
    ground_of[scene_of_ground] = grounds
    return torch.stack([ground_of[batch[spheres]], spheres])


def _ps_attr(state, index: torch.Tensor, reach: torch.Tensor) -> torch.Tensor:
    """``[v_i, n_s, clip(δ_is), clip(h_is)]`` of ps edges, ``[F, 10]`` (see the module doc);
    ``reach [N]`` float64 is ``ρ_i``."""
    planes = state.planes[index[0]].to(torch.float64)
    pos = state.pos[index[1]].to(torch.float64)
    height = ((pos - planes[:, 0:3]) * planes[:, 3:6]).sum(-1, keepdim=True)
    offset = height * planes[:, 3:6]  # the ground: an infinite plane
    bounded = state.plane_kind[index[0]] != GROUND
    if bool(bounded.any()):
        offset[bounded] = rectangle_offset(pos[bounded], planes[bounded])
    dist = offset.norm(dim=-1, keepdim=True)
    rho = reach[index[1], None]
    offset = offset * torch.where(dist > rho, rho / dist, torch.ones_like(dist))
    height = (offset * planes[:, 3:6]).sum(-1, keepdim=True)
    dtype = state.pos.dtype
    v = _velocity(state)[index[1]]
    return torch.cat([v, planes[:, 3:6].to(dtype), offset.to(dtype), height.to(dtype)], dim=-1)
