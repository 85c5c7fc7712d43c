"""Sphere–sphere (pp) and surface–sphere (ps) edges with their features, rebuilt every step.

Which pairs are linked is the connectivity's rules (:mod:`physgnn.graph.rules`: ``approach``,
``epsilon``, ``vmax``, ``vi``); a build writes the candidates they judge, keeps the accepted
ones and writes their features, in the input dtype and in raw physical units.

**Features see no absolute position.** A ps edge (the blocks of
:data:`~physgnn.graph.edges.PS`) carries the offset ``δ`` from the closest
point of the plane (the rectangle for bounded planes, the infinite plane for the ground) to
the sphere's centre, and the signed height ``h = δ·n_s``, both clipped at the sphere's reach
``ρ_i = r_i + a_i + ε`` plus ``clip_margin``: a sphere farther than the reach cannot touch the
plane before the next frame, and the clipped ground edge of a sphere in free flight is the
same at 10, 100 or 1 000 m (so gravity does not grow with altitude).

**Contacts within the frame.** A build also takes the provisional next velocities of earlier
passes of a simulator and keeps what the rules accept under any of them; a rebuild with one
more (:meth:`GraphBuilder.extend`) reuses the last build where it can
(:mod:`physgnn.graph.rebuild`: why, and when).

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

import os
from collections.abc import Sequence

import torch

from physgnn.data.state import host_sizes, scene_of_sphere
from physgnn.graph.candidates import compact, scene_counts, scene_pairs, scene_plane_pairs
from physgnn.graph.edges import Graph, paired_edges, ps_features
from physgnn.graph.neighbors import BACKENDS, radius_pairs, resolve_backend
from physgnn.graph.rebuild import Basis, grown_pairs, union_allowance, union_masks, widened
from physgnn.graph.rules import GRAVITY, SURFACE_CONTACT, ConnectivityRules, check_length
from physgnn.physics.scene import GROUND

# pp candidates: all pairs of each scene (no read-back) up to these limits, then a radius search;
# with the CPU's k-d tree, where a read-back costs nothing, the search from 8 pairs per sphere.
ALL_PAIRS_MAX, ALL_PAIRS_PER_SPHERE, CPU_PAIRS_PER_SPHERE = 1 << 18, 64, 8


class GraphBuilder(ConnectivityRules):
    """Builds a :class:`Graph` from a ``SceneState`` (one scene or a PyG ``Batch`` of them).

    ``connectivity``, ``epsilon`` (metres) and ``factor`` choose the rules
    (:class:`~physgnn.graph.rules.ConnectivityRules`); ``backend`` is
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
        super().__init__(connectivity, epsilon, factor)
        check_length("clip_margin", clip_margin)
        if backend not in BACKENDS:
            raise ValueError(
                f"unknown neighbour backend '{backend}'; choose one of {list(BACKENDS)}"
            )
        self.clip_margin = float(clip_margin)
        self.backend = backend
        self.fixed_capacity = bool(fixed_capacity)

    def __call__(self, state, provisional: Sequence[torch.Tensor] = ()) -> Graph:
        """The graph of ``state``; ``provisional``: next velocities ``[N, 3]`` of earlier
        passes (module doc, "Contacts within the frame"): a candidate is kept when the rules
        accept it under the state's own motion or under any of them."""
        return self.build(state, provisional)[0]

    def build(self, state, provisional: Sequence[torch.Tensor] = ()) -> tuple[Graph, Basis]:
        """:meth:`__call__`'s graph and the :class:`~physgnn.graph.rebuild.Basis` it was
        compacted from, which :meth:`extend` reuses."""
        batch, (spheres, planes) = scene_of_sphere(state), host_sizes(state)
        velocity = self.rule_velocity(state)  # once per build: the rules and the clip share it
        allowance = union_allowance(self, state, velocity, provisional)
        counts = scene_counts(batch, len(spheres))  # both kinds of candidate need them
        layout = self.layout_candidates(state, spheres)
        src, dst = self._pair_candidates(state, batch, allowance, spheres, counts, layout)
        plane, sphere = scene_plane_pairs(spheres, planes, state.plane_batch.long(), counts)
        candidates = (src, dst, plane, sphere)
        pp_mask, ps_mask, offset = union_masks(
            self, state, velocity, allowance, candidates, provisional
        )
        basis = Basis(allowance, candidates, (pp_mask, ps_mask), offset, layout)
        return self._compacted(state, basis), basis

    def extend(self, state, basis: Basis, provisional: Sequence[torch.Tensor]) -> tuple:
        """:meth:`build` with ``provisional``, given ``basis``, the build's with all of them
        but the last: the same graph and basis. Where a read-back costs nothing (the CPU's
        k-d tree) and the last velocity leaves every allowance as it was, the candidates and
        the earlier velocities' masks are the basis's and only the last velocity's rules run
        (:func:`~physgnn.graph.rebuild.widened`); else (a GPU would wait to ask) a whole
        build."""
        if self.fixed_capacity or resolve_backend(self.backend, state.pos) != "kdtree":
            return self.build(state, provisional)
        wider = widened(self, state, basis, provisional[-1])
        if wider is None:  # a wider reach: the candidates of the spheres it widened, added
            wider = self._regrown(state, basis, provisional)
        return self._compacted(state, wider), wider

    def _regrown(self, state, basis: Basis, provisional: Sequence[torch.Tensor]) -> Basis:
        """``basis`` under one more provisional velocity that widens some allowances: the pairs
        within the wider reach of a sphere whose allowance grew join the basis's candidates (a
        pair of two others needs no more reach than the basis's search had), and the masks of
        every velocity are taken anew under the wider allowance. The graph is the whole
        build's, edge for edge; the pair search covers the grown spheres only."""
        velocity = self.rule_velocity(state)
        allowance = union_allowance(self, state, velocity, provisional)
        src, dst, plane, sphere = basis.candidates
        if not basis.layout:  # the layout's candidates are every pair already
            grew = torch.nonzero(allowance > basis.allowance)[:, 0]  # a read-back, on the CPU
            reach = self._pair_reach(state, allowance)
            src, dst = grown_pairs(state, scene_of_sphere(state), grew, reach, (src, dst))
        candidates = (src, dst, plane, sphere)
        pp_mask, ps_mask, offset = union_masks(
            self, state, velocity, allowance, candidates, provisional
        )
        return Basis(allowance, candidates, (pp_mask, ps_mask), offset, basis.layout)

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

    def _pair_candidates(self, state, batch, allowance, spheres, counts, layout) -> tuple:
        """Candidate pairs ``(i, j)``, ``i < j``, sorted: all pairs of each scene when ``layout``
        (:meth:`layout_candidates`), else a radius search (reads sizes back,
        :func:`~physgnn.graph.neighbors.radius_pairs`); the same edges either way."""
        if layout:
            return scene_pairs(spheres, batch, counts)
        pairs = radius_pairs(state.pos, self._pair_reach(state, allowance), batch, self.backend)
        return pairs[0], pairs[1]

    def _pair_reach(self, state, allowance: torch.Tensor) -> float:
        """The radius search's reach (m): no pair farther apart can touch within the frame."""
        largest = torch.stack([state.radius.to(torch.float64).max(), allowance.max()])
        radius, allow = largest.tolist()  # one read-back: the search needs a host radius
        reach = 2 * radius + 2 * allow + self.epsilon
        return reach * (1 + 1e-9)

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
    needed &= effects[:, GRAVITY] | effects[:, SURFACE_CONTACT]
    bad = (needed & (per_scene != 1)).nonzero().flatten().tolist()
    if bad:
        raise ValueError(f"scene {bad[0]} of the batch must have exactly one ground plane (kind 0)")
