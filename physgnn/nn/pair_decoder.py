"""Pair decoder: one antisymmetric output per sphere pair, from the processor's latents."""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor, nn

from physgnn.nn.mlp import MLP


class PairDecoder(nn.Module):
    r"""Antisymmetric pair outputs (e.g. the impulse sphere j gives sphere i in a contact).

    Edges come in the *paired layout* (edge ``e + E/2`` is the reverse of edge ``e``; row 0 the
    source j, row 1 the target i). For each pair, from the node latents ``v`` and the pp edge
    latents ``e`` of both directions:

    .. math::  f_{ij} = \tfrac12\, W_2\,(h_{ij} - h_{ji}), \qquad
               h_{ij} = \mathrm{ReLU}(W_1 [v_i, v_j, e_{ij}] + b_1)

    so ``f_ji = −f_ij`` exactly for any weights, and the output does not depend on which sphere
    of the pair the graph lists first. The second layer has no bias (it would cancel).

    Shapes: ``v [N, h]``, ``edge_index [2, E]``, ``edge_attr [E, h]`` → ``[E/2, out_dim]``, row
    ``e`` the output for target ``edge_index[1, e]`` (its partner gets the opposite).
    """

    def __init__(self, hidden: int, out_dim: int):
        super().__init__()
        self.hidden = hidden
        self.mlp = MLP(3 * hidden, hidden, out_dim, out_bias=False)

    def reset_parameters(self) -> None:
        self.mlp.reset_parameters()

    def forward(self, v: Tensor, edge_index: Tensor, edge_attr: Tensor) -> Tensor:
        w_i, w_j, w_e = self.mlp.first_layer_blocks([self.hidden] * 3)
        src, dst = edge_index
        # first layer by blocks: node projections once per node, then gathered per edge
        pre = F.linear(v, w_i, self.mlp.lin1.bias)[dst] + F.linear(v, w_j)[src]
        hidden = F.relu(pre + F.linear(edge_attr, w_e))
        half = edge_index.shape[1] // 2
        return self.mlp.lin2(0.5 * (hidden[:half] - hidden[half:]))

    def flops(self, num_nodes: int, num_edges: int) -> int:
        """2 × multiply-adds of the dense layers ``forward`` runs."""
        h, out = self.hidden, self.mlp.out_dim
        return 2 * (2 * num_nodes * h * h + num_edges * h * h + (num_edges // 2) * h * out)
