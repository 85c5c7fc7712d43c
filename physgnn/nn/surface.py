"""Particle–surface (ps) message passing: static planes send messages to spheres."""

from __future__ import annotations

import torch
from torch import Tensor
from torch_geometric.nn import MessagePassing

from physgnn.nn.mlp import MLP


class SurfaceBlock(MessagePassing):
    r"""ps messages and their sum at each sphere.

    The graph is bipartite, planes → spheres: ``edge_index [2, F]`` with row 0 the plane
    index ``s`` and row 1 the sphere index ``i``. For edge ``s → i``:

    .. math::  m_{is} = \mathrm{MLP}_{ps}([v_i, e_{is}]), \qquad
               \mathrm{Agg}_i = \sum_{s \to i} m_{is}

    Planes carry no latent of their own (all that is known of a plane is on its edges) and the
    ps edge latents ``e_is`` are never updated, so only the aggregate is returned.

    Shapes: ``x [N, h]``, ``edge_index [2, F]``, ``edge_attr [F, h]`` → ``Agg [N, h]``.
    """

    def __init__(self, hidden: int):
        super().__init__(aggr="sum")
        self.hidden = hidden
        self.mlp = MLP(2 * hidden, hidden, hidden)

    def reset_parameters(self) -> None:
        super().reset_parameters()
        self.mlp.reset_parameters()

    def forward(self, x: Tensor, edge_index: Tensor, edge_attr: Tensor) -> Tensor:
        # The plane count is not needed: planes send messages but hold no latent.
        return self.propagate(edge_index, x=(None, x), edge_attr=edge_attr, size=(None, x.shape[0]))

    def message(self, x_i: Tensor, edge_attr: Tensor) -> Tensor:
        return self.mlp(torch.cat([x_i, edge_attr], dim=1))

    def flops(self, num_edges: int) -> int:
        """2 × multiply-adds of the dense layers ``forward`` runs for ``num_edges`` edges."""
        return self.mlp.flops(num_edges)
