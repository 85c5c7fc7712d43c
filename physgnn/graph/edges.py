"""The edges of a batch of scenes, as :class:`~physgnn.graph.builder.GraphBuilder` builds them:
counted (exactly the edges the rules accept) or of fixed capacity (every candidate of the
layout, with masks of the accepted ones; the builder's module doc says when and why)."""

from __future__ import annotations

from dataclasses import dataclass

import torch


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
    - ``pp_mask [E]``, ``ps_mask [F]`` (bool) of a fixed-capacity graph: the edges the rules
      accept (the rest are candidates and padding, module doc); ``None``: every edge.
    """

    pp_index: torch.Tensor
    pp_attr: torch.Tensor
    ps_index: torch.Tensor
    ps_attr: torch.Tensor
    allowance: torch.Tensor
    pp_mask: torch.Tensor | None = None
    ps_mask: torch.Tensor | None = None

    @property
    def num_pairs(self) -> int:
        """Number of unordered sphere pairs (``E / 2``; of a fixed-capacity graph: its pair
        capacity)."""
        return self.pp_index.shape[1] // 2

    @property
    def masked(self) -> bool:
        """True for a fixed-capacity graph (its edges are weighed by ``pp_mask``, ``ps_mask``)."""
        return self.pp_mask is not None

    def grew(self, earlier: Graph) -> bool:
        """True when this graph, built with more provisional velocities than ``earlier`` (so
        a superset of its edges), has edges ``earlier`` lacks: compared by size, which a
        counted graph knows on the host (nothing read back). A fixed-capacity graph keeps its
        size and may always have grown (True)."""
        if self.masked:
            return True
        sizes = (self.pp_index.shape[1], self.ps_index.shape[1])
        return sizes != (earlier.pp_index.shape[1], earlier.ps_index.shape[1])

    def pp_weight(self, like: torch.Tensor) -> torch.Tensor | None:
        """``[E]`` 1 for an accepted pp edge, 0 for the rest, in ``like``'s dtype; ``None``
        when every edge counts."""
        return None if self.pp_mask is None else self.pp_mask.to(like.dtype)

    def ps_weight(self, like: torch.Tensor) -> torch.Tensor | None:
        """``[F]``: :meth:`pp_weight` of the ps edges."""
        return None if self.ps_mask is None else self.ps_mask.to(like.dtype)

    def network_inputs(self, num_nodes: int, pp_attr: torch.Tensor, ps_attr: torch.Tensor):
        """``(pp_index, pp_attr, ps_index, ps_attr)`` for the network: a fixed-capacity graph's
        masked edges become ghost edges of node ``num_nodes`` with zero features
        (:func:`~physgnn.nn.padding.pad_graph` adds that node), so they reach only the ghost;
        the shapes are kept."""
        if self.pp_mask is None:
            return self.pp_index, pp_attr, self.ps_index, ps_attr
        pp_index = torch.where(self.pp_mask, self.pp_index, num_nodes)
        ps_index = torch.stack(
            [self.ps_index[0], torch.where(self.ps_mask, self.ps_index[1], num_nodes)]
        )
        pp_attr = torch.where(self.pp_mask[:, None], pp_attr, 0.0)
        ps_attr = torch.where(self.ps_mask[:, None], ps_attr, 0.0)
        return pp_index, pp_attr, ps_index, ps_attr

    def compacted(self) -> Graph:
        """This graph with only its accepted edges (reads their count back; itself when it has
        no masks): for what needs the exact edges, e.g. the constraint stage."""
        if self.pp_mask is None:
            return self
        half = self.pp_mask.shape[0] // 2
        pairs = self.pp_mask[:half].nonzero().flatten()
        pp = torch.cat([pairs, pairs + half])
        ps = self.ps_mask.nonzero().flatten()
        pp_index, pp_attr = self.pp_index[:, pp], self.pp_attr[pp]
        return Graph(pp_index, pp_attr, self.ps_index[:, ps], self.ps_attr[ps], self.allowance)


def paired_edges(pos, src, dst) -> tuple[torch.Tensor, torch.Tensor]:
    """pp index ``[2, E]`` in the paired layout and its features ``[E, 4]`` (class Graph)."""
    rel = pos[dst] - pos[src]
    attr = torch.cat([rel, torch.linalg.vector_norm(rel, dim=-1, keepdim=True)], dim=-1)
    index = torch.cat([torch.stack([src, dst]), torch.stack([dst, src])], dim=1)
    rev = torch.cat([-attr[:, :3], attr[:, 3:]], dim=-1)
    return index, torch.cat([attr, rev], dim=0)


def ps_features(
    state, index: torch.Tensor, offset: torch.Tensor, reach: torch.Tensor
) -> torch.Tensor:
    """``[v_i, n_s, clip(δ_is), clip(h_is)]`` of ps edges, ``[F, 10]``
    (:mod:`physgnn.graph.builder`); ``offset [F, 3]`` (float64) is δ before the clip,
    ``reach [N]`` float64 is ``ρ_i``."""
    planes = state.planes[index[0]].to(torch.float64)
    dist = offset.norm(dim=-1, keepdim=True)
    rho = reach[index[1], None]
    offset = offset * torch.where(dist > rho, rho / dist, torch.ones_like(dist))
    height = (offset * planes[:, 3:6]).sum(-1, keepdim=True)
    dtype = state.pos.dtype
    v = (state.vel[:, 0] if state.vel.dim() == 3 else state.vel)[index[1]]
    return torch.cat([v, planes[:, 3:6].to(dtype), offset.to(dtype), height.to(dtype)], dim=-1)
