"""The edges of a batch of scenes and the one contract of their features.

:class:`Graph` holds the edges :class:`~physgnn.graph.builder.GraphBuilder` builds: counted
(exactly the edges the rules accept) or of fixed capacity (every candidate of the layout, with
masks of the accepted ones; the builder's module doc says when and why).

**The edge contract.** Every edge feature is a named *block* of columns; a :class:`Layout` is
an ordered tuple of blocks, from which each block's slice follows (no column is numbered by
hand anywhere else: writers join blocks by name, readers take them by name). i is an edge's
target sphere, j the source sphere, s the plane; ``n̂_ij = (p_i − p_j)/|p_i − p_j|``.

What the graph builder writes (raw physical units, the state's dtype):

- :data:`PP` ``[E, 4]``: ``offset`` (3) ``p_i − p_j``; ``distance`` (1) ``|p_i − p_j|``.
- :data:`PS` ``[F, 10]``: ``velocity`` (3) ``v_i``; ``normal`` (3) the plane's unit normal
  ``n_s``; ``offset`` (3) ``δ_is``, from the closest point of plane s (its rectangle; the
  ground: the infinite plane) to the centre; ``height`` (1) ``h_is = δ_is·n_s`` (signed);
  ``δ_is`` clipped at the sphere's reach plus ``clip_margin`` (h from the clipped δ).

What the learned simulator appends for its network (:mod:`physgnn.models.contact_inputs`;
ℓ the model's ``length_scale``, σ_v the RMS of the velocity std), after the builder's blocks
scaled (lengths / ℓ, the ps velocity / the velocity std per axis, the normal as it is):

- :data:`PP_CONTACT` ``[E, 2]`` (``contact_features`` without ``relative_pairs``): ``gap``
  ``(|p_i − p_j| − r_i − r_j)/ℓ``; ``normal_speed`` ``(v_i − v_j)·n̂_ij/σ_v``.
- :func:`pair_layout` ``[E, 5 + 3·(H+1) (+1) (+2)]`` (``relative_pairs``): ``gap``,
  ``normal_speed``, ``tangential_speed`` ``|tangential part of v_i − v_j|/σ_v``,
  ``velocity_history`` (3 per frame) ``v_i − v_j`` of the H+1 latest frames / σ_v, ``radii``
  (2) ``(r_i, r_j)/ℓ``, then ``mass_ratio`` (1) ``m_i/(m_i + m_j)`` with ``mass_ratio``, then
  ``material`` (2) ``(e_i·e_j, μ_i·μ_j)`` with ``material_features``.
- :data:`PS_CONTACT` ``[F, 3]`` (``contact_features``): ``clearance`` ``(h − r_i)/ℓ``,
  ``normal_speed`` ``v_i·n_s/σ_v``, ``tangential_speed`` ``|v_i − (v_i·n_s) n_s|/σ_v``.
- :data:`PS_MATERIAL` ``[F, 2]`` (``plane_materials``): ``material`` ``(e_i·e_s, μ_i·μ_s)``.

:func:`pp_inputs` and :func:`ps_inputs` are the network's whole input layouts for a model's
options (their widths are the network's ``pp_in`` and ``ps_in``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class Layout:
    """Named blocks of edge-feature columns, in order: ``blocks`` is a tuple of
    ``(name, width)``; block k takes the columns after blocks 0..k−1, so the blocks tile
    ``[0, width)`` with no gap and no overlap."""

    blocks: tuple[tuple[str, int], ...]

    def __post_init__(self):
        names = [name for name, _ in self.blocks]
        if len(set(names)) != len(names) or any(width < 1 for _, width in self.blocks):
            raise ValueError(f"edge blocks need unique names and widths >= 1: {self.blocks}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.blocks)

    @property
    def width(self) -> int:
        """The number of columns of the whole layout."""
        return sum(width for _, width in self.blocks)

    def slice(self, name: str) -> slice:
        """The columns of block ``name``."""
        start = 0
        for block, width in self.blocks:
            if block == name:
                return slice(start, start + width)
            start += width
        raise KeyError(f"no edge block {name!r}; the blocks are {list(self.names)}")

    def take(self, attr: torch.Tensor, name: str) -> torch.Tensor:
        """``[rows, width of name]``: block ``name`` of ``attr [rows, self.width]``."""
        return attr[:, self.slice(name)]

    def join(self, parts: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """``[rows, self.width]``: the blocks ``parts`` (name → ``[rows, width]``), each block
        once, concatenated in the layout's order."""
        if set(parts) != set(self.names):
            raise ValueError(f"edge blocks {sorted(parts)} given, the layout has {self.names}")
        for name, width in self.blocks:
            if parts[name].shape[-1] != width:
                raise ValueError(
                    f"edge block {name!r} has {parts[name].shape[-1]} columns, not {width}"
                )
        return torch.cat([parts[name] for name in self.names], dim=-1)

    def __add__(self, other: Layout) -> Layout:
        """This layout's blocks, then ``other``'s."""
        return Layout(self.blocks + other.blocks)


PP = Layout((("offset", 3), ("distance", 1)))
PS = Layout((("velocity", 3), ("normal", 3), ("offset", 3), ("height", 1)))
PP_CONTACT = Layout((("gap", 1), ("normal_speed", 1)))
PS_CONTACT = Layout((("clearance", 1), ("normal_speed", 1), ("tangential_speed", 1)))
PS_MATERIAL = Layout((("material", 2),))
NOTHING = Layout(())


def pair_layout(history: int, mass_ratio: bool, materials: bool) -> Layout:
    """The relative pair inputs (module doc) for ``history`` = H + 1 velocities."""
    blocks = [("gap", 1), ("normal_speed", 1), ("tangential_speed", 1)]
    blocks += [("velocity_history", 3 * history), ("radii", 2)]
    blocks += [("mass_ratio", 1)] if mass_ratio else []
    blocks += [("material", 2)] if materials else []
    return Layout(tuple(blocks))


def pp_inputs(
    history: int, relative_pairs: bool, mass_ratio: bool, materials: bool, contact: bool
) -> Layout:
    """The network's pp input: :data:`PP`, then :func:`pair_layout` with ``relative_pairs``,
    else :data:`PP_CONTACT` with ``contact`` (``contact_features``)."""
    if relative_pairs:
        return PP + pair_layout(history, mass_ratio, materials)
    return PP + (PP_CONTACT if contact else NOTHING)


def ps_inputs(contact: bool, plane_materials: bool) -> Layout:
    """The network's ps input: :data:`PS`, then :data:`PS_CONTACT` with ``contact``
    (``contact_features``), then :data:`PS_MATERIAL` with ``plane_materials``."""
    return PS + (PS_CONTACT if contact else NOTHING) + (PS_MATERIAL if plane_materials else NOTHING)


@dataclass
class Graph:
    """Edges of a batch of scenes (E pp edges, F ps edges; PyG flow source → target).

    - ``pp_index [2, E]``: row 0 source j, row 1 target i, *paired layout*: columns
      ``[0, E/2)`` hold each unordered pair once (source < target, sorted), columns
      ``[E/2, E)`` the same pairs reversed, so the reverse of edge e is edge ``e + E/2``.
    - ``pp_attr [E, PP.width]``: the blocks of :data:`PP` (module doc).
    - ``ps_index [2, F]``: row 0 plane index into ``state.planes``, row 1 sphere index,
      sorted by (plane, sphere).
    - ``ps_attr [F, PS.width]``: the blocks of :data:`PS` (module doc).
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
    """pp index ``[2, E]`` in the paired layout and its :data:`PP` features ``[E, 4]``
    (class Graph)."""
    rel = pos[dst] - pos[src]
    dist = torch.linalg.vector_norm(rel, dim=-1, keepdim=True)
    index = torch.cat([torch.stack([src, dst]), torch.stack([dst, src])], dim=1)
    forward = PP.join({"offset": rel, "distance": dist})
    reverse = PP.join({"offset": -rel, "distance": dist})
    return index, torch.cat([forward, reverse], dim=0)


def ps_features(
    state, index: torch.Tensor, offset: torch.Tensor, clip: torch.Tensor
) -> torch.Tensor:
    """The :data:`PS` features ``[F, 10]`` of ps edges ``index [2, F]``
    (:mod:`physgnn.graph.builder`); ``offset [F, 3]`` (float64) is δ before the clip,
    ``clip [N]`` float64 the length each sphere's δ is clipped at."""
    planes = state.planes[index[0]].to(torch.float64)
    dist = offset.norm(dim=-1, keepdim=True)
    rho = clip[index[1], None]
    offset = offset * torch.where(dist > rho, rho / dist, torch.ones_like(dist))
    height = (offset * planes[:, 3:6]).sum(-1, keepdim=True)
    dtype = state.pos.dtype
    v = (state.vel[:, 0] if state.vel.dim() == 3 else state.vel)[index[1]]
    blocks = {"velocity": v, "normal": planes[:, 3:6].to(dtype)}
    return PS.join(blocks | {"offset": offset.to(dtype), "height": height.to(dtype)})
