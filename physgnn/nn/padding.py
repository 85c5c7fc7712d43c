"""Graphs padded to capacity buckets: one set of tensor shapes for many graph sizes.

A captured step (CUDA graphs, ``torch.compile`` without dynamic shapes) replays fixed shapes,
but the node count N, the pp edge count E and the ps edge count F change every step.
:func:`pad_graph` rounds N + 1, E/2 and F up to the next :func:`bucket` (powers of
``2^(1/4)``: at most 19 % of padding) and fills the rest with a *ghost*: one extra node (index
N, zero features, material 0) and pp and ps edges from the ghost to itself, with zero
features. The network is node- and edge-local with sums over each node's incoming edges, so
the ghost's edges reach only the ghost, and the real nodes' outputs are the unpadded ones up to
float rounding. The pp edges keep the paired layout (the dummy pairs close each half).

Shapes: ``x [N, d]`` → ``[N', d]``; ``pp_index [2, E]`` → ``[2, E']``, ``pp_attr [E, p]`` →
``[E', p]``; ``ps_index [2, F]`` → ``[2, F']`` (dummy edges name plane 0), ``ps_attr [F, q]`` →
``[F', q]``; ``material [N]`` → ``[N']``.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

SMALLEST = 8  # no bucket below this


def bucket(n: int, steps_per_doubling: int = 4) -> int:
    """The smallest capacity ``≥ n`` of the form ``ceil(2^(k / steps_per_doubling))``."""
    if n <= SMALLEST:
        return SMALLEST
    k = math.ceil(steps_per_doubling * math.log2(n) - 1e-9)
    return max(n, math.ceil(2 ** (k / steps_per_doubling)))


def pad_graph(
    x: Tensor,
    pp_index: Tensor,
    pp_attr: Tensor,
    ps_index: Tensor,
    ps_attr: Tensor,
    material: Tensor | None = None,
) -> tuple[tuple[Tensor, ...], int]:
    """``((x, pp_index, pp_attr, ps_index, ps_attr, material), N)``: the graph padded as the
    module doc says, and the number of real nodes (the first N rows of the output)."""
    n, half, f = x.shape[0], pp_index.shape[1] // 2, ps_index.shape[1]
    extra_nodes, extra_pairs = bucket(n + 1) - n, bucket(half) - half
    extra_ps = bucket(f) - f

    def ghost(count: int) -> Tensor:
        return pp_index.new_full((count,), n)

    x = torch.cat([x, x.new_zeros(extra_nodes, x.shape[1])])
    dummy = torch.stack([ghost(extra_pairs), ghost(extra_pairs)])
    pp_index = torch.cat([pp_index[:, :half], dummy, pp_index[:, half:], dummy], 1)
    zeros = pp_attr.new_zeros(extra_pairs, pp_attr.shape[1])
    pp_attr = torch.cat([pp_attr[:half], zeros, pp_attr[half:], zeros])
    ps_index = torch.cat([ps_index, torch.stack([ghost(extra_ps) * 0, ghost(extra_ps)])], 1)
    ps_attr = torch.cat([ps_attr, ps_attr.new_zeros(extra_ps, ps_attr.shape[1])])
    if material is not None:
        material = torch.cat([material, material.new_zeros(extra_nodes)])
    return (x, pp_index, pp_attr, ps_index, ps_attr, material), n
