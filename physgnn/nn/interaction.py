"""Particle–particle (pp) message passing with Newton's third law built in."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor
from torch_geometric.nn import MessagePassing

from physgnn.nn.aggregation import IndexSum
from physgnn.nn.mlp import MLP

CONCAT_MODES = ("auto", "always", "never")


class InteractionBlock(MessagePassing):
    r"""pp messages and their sum at each sphere.

    Edges come in the *paired layout*: ``edge_index [2, E]``, row 0 the source ``j``, row 1
    the target ``i``, and the reverse of edge ``e`` is edge ``e + E/2``. For edge ``j → i``:

    .. math::  m_{ij} = \mathrm{MLP}_{pp}([v_i, v_j, e_{ij}]), \qquad
               \mathrm{Agg}_i = \sum_{j \to i} m_{ij}

    With ``third_law=True`` the message of a pair is antisymmetrised,

    .. math::  m_{ij} = \tfrac12\,[f(v_i, v_j, e_{ij}) - f(v_j, v_i, e_{ji})] = -m_{ji},

    computed as ``m_ij = ½ W_2 (h_ij − h_ji)`` from the hidden units ``h = ReLU(W_1 [·] + b_1)``
    of both directions (the second layer is linear: it runs once per pair, not per edge),
    so the messages of a pair cancel exactly (``Σ_i Agg_i = 0``) *and* do not depend on which
    sphere of the pair the graph lists first (evaluating ``f`` on one direction only and
    negating it would make the output depend on sphere numbering: no permutation
    equivariance). With ``third_law=False`` every edge is computed on its own (GNS style).

    ``concat_trick`` chooses how the first layer ``W [v_i, v_j, e] + b`` is evaluated:
    ``"never"``: on the concatenated ``[E, 3h]`` input (the reference path);
    ``"always"``: as ``(W_i v)[i] + (W_j v)[j] + W_e e + b`` with the two node projections
    computed once per node (``2N`` rows instead of ``E``); ``"auto"``: the concat trick
    when it is cheaper, i.e. when ``N < E``, and always in compiled code (one graph for every
    size). Both paths give the same numbers up to float rounding.

    The hidden units are computed by ``edge_updater``, the messages from them (they are also
    the pp edge-latent update ``e_ij += m_ij``, so the caller needs them) and summed by
    ``propagate``.

    Shapes: ``x [N, h]``, ``edge_index [2, E]``, ``edge_attr [E, h]`` →
    ``(Agg [N, h], messages [E, h])``.
    """

    def __init__(self, hidden: int, third_law: bool = True, concat_trick: str = "auto"):
        super().__init__(aggr=IndexSum())
        if concat_trick not in CONCAT_MODES:
            raise ValueError(f"concat_trick must be one of {CONCAT_MODES}, got {concat_trick!r}")
        self.hidden, self.third_law, self.concat_trick = hidden, third_law, concat_trick
        # An output bias cancels in the antisymmetrised message: leave it out (no dead weight).
        self.mlp = MLP(3 * hidden, hidden, hidden, out_bias=not third_law)

    def reset_parameters(self) -> None:
        super().reset_parameters()
        self.mlp.reset_parameters()

    def forward(self, x: Tensor, edge_index: Tensor, edge_attr: Tensor) -> tuple[Tensor, Tensor]:
        num_msg = edge_index.shape[1]
        concat = self.uses_concat(x.shape[0], num_msg)
        if concat:
            w_i, w_j, _ = self.mlp.first_layer_blocks([self.hidden] * 3)
            # (source, target) projections; the bias is added once per node, not per edge
            pair = (F.linear(x, w_j), F.linear(x, w_i, self.mlp.lin1.bias))
        else:
            pair = (x, x)
        hidden = self.edge_updater(edge_index, x=pair, edge_attr=edge_attr, concat=concat)
        if self.third_law:
            half = num_msg // 2
            m_pair = self.mlp.lin2(0.5 * (hidden[:half] - hidden[half:]))
            m = torch.cat([m_pair, -m_pair])
        else:
            m = self.mlp.lin2(hidden)
        return self.propagate(edge_index, m=m, size=(x.shape[0], x.shape[0])), m

    def edge_update(self, x_i: Tensor, x_j: Tensor, edge_attr: Tensor, concat: bool) -> Tensor:
        """Hidden units ``ReLU(W_1 [v_i, v_j, e_ij] + b_1)`` ``[E, h]``; ``x_i``, ``x_j`` are
        the node latents or, when ``concat``, their projections ``W_i v_i + b`` and ``W_j v_j``."""
        if concat:
            w_e = self.mlp.first_layer_blocks([self.hidden] * 3)[2]
            return F.relu(torch.addmm(x_i + x_j, edge_attr, w_e.t()))
        return F.relu(self.mlp.lin1(torch.cat([x_i, x_j, edge_attr], dim=1)))

    def message(self, m: Tensor) -> Tensor:
        return m

    def uses_concat(self, num_nodes: int, num_msg: int) -> bool:
        if self.concat_trick == "auto":
            # compiled code takes one path, so that sizes crossing over do not compile anew
            return torch.compiler.is_compiling() or num_nodes < num_msg
        return self.concat_trick == "always"

    def flops(self, num_nodes: int, num_edges: int) -> int:
        """2 × multiply-adds of the dense layers ``forward`` runs for this graph size."""
        num_msg = num_edges
        if num_msg == 0:
            return 0
        h = self.hidden
        if self.uses_concat(num_nodes, num_msg):
            first = 2 * num_nodes * h * h + num_msg * h * h
        else:
            first = num_msg * 3 * h * h
        second = (num_msg // 2 if self.third_law else num_msg) * h * h
        return 2 * (first + second)
