"""Particle–surface (ps) message passing: static planes send messages to spheres."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor
from torch_geometric.nn import MessagePassing

from physgnn.nn.aggregation import IndexSum
from physgnn.nn.mlp import MLP


class SurfaceBlock(MessagePassing):
    r"""ps messages and their sum at each sphere.

    The graph is bipartite, planes → spheres: ``edge_index [2, F]`` with row 0 the plane
    index ``s`` and row 1 the sphere index ``i``. For edge ``s → i``, with
    ``MLP_ps(x) = W_2\,\mathrm{ReLU}(W_1 x + b_1) + b_2``:

    .. math::  m_{is} = \mathrm{MLP}_{ps}([v_i, e_{is}]), \qquad
               \mathrm{Agg}_i = \sum_{s \to i} m_{is}
               = W_2 \sum_{s \to i} h_{is} + d_i\, b_2, \quad
               h_{is} = \mathrm{ReLU}(W_{1v} v_i + W_{1e} e_{is} + b_1)

    (``d_i`` the number of ps edges of sphere i). The second layer is linear, so it is applied
    once per sphere to the summed hidden units ``h`` rather than once per edge, and the first
    layer's sphere part ``W_{1v} v_i`` once per sphere: the same function as the MLP on the
    concatenated input, up to float rounding, with ``N + F`` instead of ``2F`` rows of products.

    Planes carry no latent of their own (all that is known of a plane is on its edges) and the
    ps edge latents ``e_is`` are never updated, so only the aggregate is returned.

    Shapes: ``x [N, h]``, ``edge_index [2, F]``, ``edge_attr [F, h]`` → ``Agg [N, h]``.
    """

    def __init__(self, hidden: int):
        super().__init__(aggr=IndexSum())
        self.hidden = hidden
        self.mlp = MLP(2 * hidden, hidden, hidden)

    def reset_parameters(self) -> None:
        super().reset_parameters()
        self.mlp.reset_parameters()

    def forward(self, x: Tensor, edge_index: Tensor, edge_attr: Tensor) -> Tensor:
        w_v, w_e = self.mlp.first_layer_blocks([self.hidden, self.hidden])
        # The plane count is not needed: planes send messages but hold no latent.
        hidden = self.propagate(
            edge_index,
            x=(None, F.linear(x, w_v)),
            edge_attr=torch.addmm(self.mlp.lin1.bias, edge_attr, w_e.t()),
            size=(None, x.shape[0]),
        )
        # Edge count per sphere by an index_add_ (bincount would read its size back from a GPU).
        sphere = edge_index[1]
        degree = x.new_zeros(x.shape[0]).index_add_(0, sphere, x.new_ones(sphere.shape[0]))
        return torch.addmm(degree[:, None] * self.mlp.lin2.bias, hidden, self.mlp.lin2.weight.t())

    def message(self, x_i: Tensor, edge_attr: Tensor) -> Tensor:
        """Hidden units ``h_is [F, h]`` from the projections ``W_{1v} v_i`` and
        ``W_{1e} e_is + b_1``."""
        return F.relu(x_i + edge_attr)

    def flops(self, num_nodes: int, num_edges: int) -> int:
        """2 × multiply-adds of the dense layers ``forward`` runs (``N`` + ``F`` rows of the
        first layer's halves, ``N`` rows of the second layer)."""
        h = self.hidden
        return 2 * h * h * (2 * num_nodes + num_edges)
