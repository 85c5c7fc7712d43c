"""The multi-layer perceptron used everywhere in the network: Linear → ReLU → Linear, with an
optional LayerNorm on the output (as GNS has on every MLP but the decoder)."""

from __future__ import annotations

import torch.nn.functional as F
from torch import Tensor, nn


class MLP(nn.Module):
    """``[*, in_dim] → [*, out_dim]`` through one hidden layer of ``hidden`` ReLU units.

    Both layers are plain ``nn.Linear`` so the work is two dense matrix products, countable by
    :meth:`flops`. :meth:`first_layer_blocks` and :meth:`finish` let a caller evaluate the first
    layer on a concatenated input ``[a, b, c]`` as ``W_a a + W_b b + W_c c`` (the "concat
    trick"): each block can then be applied where it is cheapest (e.g. once per node).
    ``layer_norm``: ``LayerNorm(out_dim)`` after the second layer (``forward`` and ``finish``).
    """

    def __init__(
        self,
        in_dim: int,
        hidden: int,
        out_dim: int,
        out_bias: bool = True,
        layer_norm: bool = False,
    ):
        super().__init__()
        self.in_dim, self.hidden, self.out_dim = in_dim, hidden, out_dim
        self.lin1 = nn.Linear(in_dim, hidden)
        self.lin2 = nn.Linear(hidden, out_dim, bias=out_bias)
        self.norm = nn.LayerNorm(out_dim) if layer_norm else None

    def reset_parameters(self) -> None:
        for layer in (self.lin1, self.lin2, self.norm):
            if layer is not None:
                layer.reset_parameters()

    def forward(self, x: Tensor) -> Tensor:
        return self.finish(self.lin1(x))

    def first_layer_blocks(self, sizes: list[int]) -> tuple[Tensor, ...]:
        """Column blocks of the first weight, ``W = [W_1 | W_2 | …]``, each ``[hidden, size_k]``."""
        return self.lin1.weight.split(sizes, dim=1)

    def finish(self, pre: Tensor) -> Tensor:
        """The rest of the MLP from the first layer's pre-activation (bias included):
        ``[*, hidden] → [*, out_dim]``."""
        out = self.lin2(F.relu(pre))
        return out if self.norm is None else self.norm(out)

    def flops(self, rows: int) -> int:
        """2 × multiply-adds of both layers applied to ``rows`` inputs."""
        return 2 * rows * (self.in_dim * self.hidden + self.hidden * self.out_dim)
