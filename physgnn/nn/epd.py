"""Encode–process–decode graph network (report §3.2.3–3.2.5) on plain tensors."""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from physgnn.nn.aggregation import inverse_degree
from physgnn.nn.interaction import InteractionBlock
from physgnn.nn.mlp import MLP
from physgnn.nn.pair_decoder import PairDecoder
from physgnn.nn.surface import SurfaceBlock

AGGREGATIONS = ("sum", "mean")


@dataclass(frozen=True)
class Widths:
    """The network's input and output widths, which the simulator's inputs set (not config):
    ``node_in`` numbers per sphere, ``pp_in`` per pp edge, ``ps_in`` per ps edge (the defaults:
    the ``PP`` and ``PS`` widths of ``physgnn.graph.edges``), ``out_dim`` per sphere out and
    ``pair_out`` antisymmetric numbers per pp pair (0: no pair decoder)."""

    node_in: int
    pp_in: int = 4
    ps_in: int = 10
    out_dim: int = 6
    pair_out: int = 0


class ProcessorBlock(nn.Module):
    r"""One GN block with its own weights:

    .. math::  \mathrm{Agg}_i = \sum_{j \to i} m_{ij} + \sum_{s \to i} m_{is}, \quad
               v_i \mathrel{+}= \mathrm{MLP}_v([v_i, \mathrm{Agg}_i]), \quad
               e_{ij} \mathrel{+}= m_{ij}

    With ``aggregation="mean"`` each sum is divided by the sphere's number of edges of its
    kind (``inv_pp``, ``inv_ps`` ``[N, 1]`` from :func:`~physgnn.nn.aggregation.inverse_degree`):
    the aggregate stays bounded as contacts grow from 1 to 12. ``None``: plain sums.
    An interaction with no edge (``E == 0``, ``e_ps is None``) runs no MLP at all.
    ``layer_norm``: the node update ``MLP_v`` ends in a LayerNorm (messages never do: a
    norm's bias would break the exact antisymmetry ``m_ji = −m_ij``).
    Shapes: ``v [N, h]``, ``pp_index [2, E]``, ``e_pp [E, h]``, ``ps_index [2, F]``,
    ``e_ps [F, h] | None`` → ``(v [N, h], e_pp [E, h])``.
    """

    def __init__(
        self,
        hidden: int,
        third_law: bool,
        use_surfaces: bool,
        concat_trick: str,
        layer_norm: bool = False,
    ):
        super().__init__()
        self.pp = InteractionBlock(hidden, third_law, concat_trick)
        self.ps = SurfaceBlock(hidden) if use_surfaces else None
        self.node = MLP(2 * hidden, hidden, hidden, layer_norm=layer_norm)

    def reset_parameters(self) -> None:
        for module in (self.pp, self.ps, self.node):
            if module is not None:
                module.reset_parameters()

    def forward(
        self,
        v: Tensor,
        pp_index: Tensor,
        e_pp: Tensor,
        ps_index: Tensor,
        e_ps: Tensor | None,
        inv_pp: Tensor | None = None,
        inv_ps: Tensor | None = None,
    ) -> tuple[Tensor, Tensor]:
        agg, e_pp = self.aggregate(v, pp_index, e_pp, ps_index, e_ps, inv_pp, inv_ps)
        return self.update(v, agg), e_pp

    def aggregate(self, v, pp_index, e_pp, ps_index, e_ps, inv_pp=None, inv_ps=None):
        """``(Agg [N, h] | None, e_pp [E, h])``: the block's aggregate (None: no edges) and
        its updated pp edge latents (the arguments of :meth:`forward`)."""
        aggs = []
        if pp_index.shape[1] > 0:
            agg_pp, m = self.pp(v, pp_index, e_pp)
            aggs.append(agg_pp if inv_pp is None else agg_pp * inv_pp)
            e_pp = e_pp + m
        if e_ps is not None:
            agg_ps = self.ps(v, ps_index, e_ps)
            aggs.append(agg_ps if inv_ps is None else agg_ps * inv_ps)
        return (sum(aggs[1:], aggs[0]) if aggs else None), e_pp

    def update(self, v: Tensor, agg: Tensor | None) -> Tensor:
        """``v [N, h]`` + ``MLP_v([v, Agg])`` (``agg [N, h]``; None: no edges)."""
        # MLP_v([v, Agg]) with its first layer split, W_v v + W_a Agg: no [N, 2h] copy, and no
        # product at all on an Agg that is zero (no edges).
        w_v, w_a = self.node.first_layer_blocks([v.shape[1], v.shape[1]])
        pre = torch.addmm(self.node.lin1.bias, v, w_v.t())
        if agg is not None:
            pre = torch.addmm(pre, agg, w_a.t())
        return v + self.node.finish(pre)

    def flops(self, num_nodes: int, num_pp_edges: int, num_ps_edges: int) -> int:
        has_ps = self.ps is not None and num_ps_edges > 0
        total = self.pp.flops(num_nodes, num_pp_edges) + self.node.flops(num_nodes)
        if num_pp_edges == 0 and not has_ps:  # no Agg: its half of the first layer is skipped
            total -= 2 * num_nodes * self.node.hidden * (self.node.in_dim // 2)
        return total + (self.ps.flops(num_nodes, num_ps_edges) if has_ps else 0)


class EncodeProcessDecode(nn.Module):
    """Node, pp and ps encoders to width ``hidden``; ``M`` :class:`ProcessorBlock`; a decoder
    to ``out_dim`` numbers per sphere (report: v and ω, 6); the widths are one
    :class:`Widths` (``widths``).

    ``forward(x [N, node_in], pp_index [2, E], pp_attr [E, pp_in], ps_index [2, F],
    ps_attr [F, ps_in], material [N] | None) -> [N, out_dim]``; the simulator sets ``pp_in``
    and ``ps_in`` from its edge layouts (``physgnn.graph.edges``, whose ``PP`` and ``PS``
    widths are the defaults here: tested, as ``nn`` imports nothing of physgnn).

    - pp edges are in the paired layout (edge ``e + E/2`` is the reverse of edge ``e``); with
      ``third_law`` the messages of a pair are exactly opposite (see :class:`InteractionBlock`).
    - ``E == 0`` runs neither the pp encoder nor any pp MLP; ``F == 0`` or
      ``use_surfaces=False`` runs no ps MLP (ps inputs are then ignored). The GNS-style
      baseline is ``third_law=False, use_surfaces=False`` (its boundary distances are part
      of ``x``).
    - With ``num_materials > 0``, a learned ``material_dim`` embedding of ``material`` is
      concatenated to ``x``; without, ``material`` is ignored.
    - ``concat_trick`` ("auto", "always", "never") picks how the pp MLP's first layer is
      evaluated; all give the same numbers up to float rounding.
    - ``layer_norm``: the three encoders and every node update end in a LayerNorm (GNS does
      this on every MLP but the decoder; here the message MLPs have none, see
      :class:`ProcessorBlock`).
    - ``aggregation``: ``"mean"`` (bounded in the number of contacts, :class:`ProcessorBlock`)
      or ``"sum"`` (the report's).
    - ``widths.pair_out`` > 0: a :class:`~physgnn.nn.pair_decoder.PairDecoder` to ``pair_out``
      antisymmetric numbers per pp pair (:meth:`forward_pairs`; the default model's pair
      impulses).

    The defaults are the default model's network (``conf/model/baseline.yaml``, ``network``).
    """

    def __init__(
        self,
        widths: Widths,
        hidden: int = 128,
        M: int = 5,
        third_law: bool = True,
        use_surfaces: bool = True,
        num_materials: int = 0,
        material_dim: int = 0,
        concat_trick: str = "auto",
        layer_norm: bool = False,
        aggregation: str = "mean",
    ):
        super().__init__()
        node_in, pp_in, ps_in = widths.node_in, widths.pp_in, widths.ps_in
        out_dim, pair_out = widths.out_dim, widths.pair_out
        if min(node_in, pp_in, ps_in, hidden, out_dim) < 1 or M < 0:
            raise ValueError("dimensions must be positive and M >= 0")
        if aggregation not in AGGREGATIONS:
            raise ValueError(f"aggregation must be one of {AGGREGATIONS}, got {aggregation!r}")
        self.aggregation = aggregation
        if (num_materials > 0) != (material_dim > 0):
            raise ValueError("num_materials and material_dim must be both positive or both 0")
        self.node_in, self.pp_in, self.ps_in = node_in, pp_in, ps_in
        self.third_law, self.use_surfaces = third_law, use_surfaces
        self.material = nn.Embedding(num_materials, material_dim) if num_materials else None
        norm = {"layer_norm": bool(layer_norm)}
        self.node_encoder = MLP(node_in + material_dim, hidden, hidden, **norm)
        self.pp_encoder = MLP(pp_in, hidden, hidden, **norm)
        self.ps_encoder = MLP(ps_in, hidden, hidden, **norm) if use_surfaces else None
        self.blocks = nn.ModuleList(
            ProcessorBlock(hidden, third_law, use_surfaces, concat_trick, **norm) for _ in range(M)
        )
        self.decoder = MLP(hidden, hidden, out_dim)
        self.pair_decoder = PairDecoder(hidden, pair_out) if pair_out > 0 else None

    def reset_parameters(self) -> None:
        for module in self.children():
            if module is not self.blocks:
                module.reset_parameters()
        for block in self.blocks:
            block.reset_parameters()

    def forward(
        self,
        x: Tensor,
        pp_index: Tensor,
        pp_attr: Tensor,
        ps_index: Tensor,
        ps_attr: Tensor,
        material: Tensor | None = None,
    ) -> Tensor:
        """``[N, out_dim]`` (class doc)."""
        return self.decoder(self.process(x, pp_index, pp_attr, ps_index, ps_attr, material)[0])

    def forward_pairs(self, x, pp_index, pp_attr, ps_index, ps_attr, material=None):
        """``([N, out_dim], [E/2, pair_out])``: :meth:`forward` and the pair decoder's
        antisymmetric outputs (needs ``pair_out > 0``)."""
        if self.pair_decoder is None:
            raise ValueError("forward_pairs needs a network built with pair_out > 0")
        v, e_pp = self.process(x, pp_index, pp_attr, ps_index, ps_attr, material)
        if pp_index.shape[1] == 0:
            return self.decoder(v), v.new_zeros(0, self.pair_decoder.mlp.out_dim)
        return self.decoder(v), self.pair_decoder(v, pp_index, e_pp)

    def process(self, x, pp_index, pp_attr, ps_index, ps_attr, material=None):
        """``(v [N, hidden], e_pp [E, hidden])``: the latents after the M blocks."""
        self._check(x, pp_index, pp_attr, ps_index, ps_attr, material)
        v, e_pp, e_ps, inv_pp, inv_ps = self.encode(
            x, pp_index, pp_attr, ps_index, ps_attr, material
        )
        for block in self.blocks:
            v, e_pp = block(v, pp_index, e_pp, ps_index, e_ps, inv_pp, inv_ps)
        return v, e_pp

    def encode(self, x, pp_index, pp_attr, ps_index, ps_attr, material=None) -> tuple:
        """``(v [N, h], e_pp [E, h], e_ps [F, h] | None, inv_pp [N, 1] | None, inv_ps [N, 1]
        | None)``: the encoded latents (``e_ps`` None: no ps MLP runs) and, with the mean
        aggregation, the inverse degrees the blocks weigh their sums by."""
        v = self.node_encoder(self._node_input(x, material))
        has_pp = pp_index.shape[1] > 0
        e_pp = self.pp_encoder(pp_attr) if has_pp else pp_attr.new_zeros(0, v.shape[1])
        has_ps = self.ps_encoder is not None and ps_index.shape[1] > 0
        e_ps = self.ps_encoder(ps_attr) if has_ps else None
        inv_pp = inv_ps = None
        if self.aggregation == "mean":
            inv_pp = inverse_degree(pp_index[1], v.shape[0], v) if has_pp else None
            inv_ps = inverse_degree(ps_index[1], v.shape[0], v) if has_ps else None
        return v, e_pp, e_ps, inv_pp, inv_ps

    def flops_per_step(self, num_nodes: int, num_pp_edges: int, num_ps_edges: int) -> int:
        """2 × multiply-adds of every dense layer one ``forward`` runs on a graph of this size
        (the same layers ``forward`` skips are left out; gathers, sums, ReLUs not counted)."""
        n, e = num_nodes, num_pp_edges
        f = num_ps_edges if self.ps_encoder is not None else 0
        total = self.node_encoder.flops(n) + self.decoder.flops(n)
        total += self.pp_encoder.flops(e) + (self.ps_encoder.flops(f) if f else 0)
        total += self.pair_decoder.flops(n, e) if self.pair_decoder is not None and e else 0
        return total + sum(block.flops(n, e, f) for block in self.blocks)

    def _node_input(self, x: Tensor, material: Tensor | None) -> Tensor:
        if self.material is None:
            return x
        if material is None:
            raise ValueError("this model embeds materials: pass material [N]")
        # The range check reads a value back (a GPU sync): only with PHYSGNN_CHECKS=1; without
        # it an id out of range fails in the embedding itself.
        checked = os.environ.get("PHYSGNN_CHECKS") == "1" and material.numel()
        if checked and int(material.max()) >= self.material.num_embeddings:
            raise ValueError(
                f"material id {int(material.max())} out of range for "
                f"num_materials={self.material.num_embeddings}"
            )
        return torch.cat([x, self.material(material)], dim=1)

    def _check(self, x, pp_index, pp_attr, ps_index, ps_attr, material) -> None:
        n, e = x.shape[0], pp_index.shape[-1]
        if x.dim() != 2 or x.shape[1] != self.node_in:
            raise ValueError(f"x must be [N, {self.node_in}], got {list(x.shape)}")
        if pp_index.dim() != 2 or pp_index.shape[0] != 2 or list(pp_attr.shape) != [e, self.pp_in]:
            raise ValueError(
                f"pp_index must be [2, E] and pp_attr [E, {self.pp_in}], "
                f"got {list(pp_index.shape)} and {list(pp_attr.shape)}"
            )
        if self.use_surfaces and (
            ps_index.dim() != 2
            or ps_index.shape[0] != 2
            or list(ps_attr.shape) != [ps_index.shape[1], self.ps_in]
        ):
            raise ValueError(
                f"ps_index must be [2, F] and ps_attr [F, {self.ps_in}], "
                f"got {list(ps_index.shape)} and {list(ps_attr.shape)}"
            )
        if material is not None and list(material.shape) != [n]:
            raise ValueError(f"material must be [N] = [{n}], got {list(material.shape)}")
        # The layout check reads a value back (a GPU sync): only with PHYSGNN_CHECKS=1.
        if self.third_law and e > 0 and (e % 2 or os.environ.get("PHYSGNN_CHECKS") == "1"):
            half = e // 2
            if e % 2 or not torch.equal(pp_index[:, half:], pp_index[:, :half].flip(0)):
                raise ValueError(
                    "third_law needs pp edges in the paired layout "
                    "(edge e + E/2 must be the reverse of edge e)"
                )
