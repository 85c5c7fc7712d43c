"""Sum aggregation by ``index_add_``: the messages' sum at each target node."""

from __future__ import annotations

from torch import Tensor
from torch_geometric.nn.aggr import Aggregation


class IndexSum(Aggregation):
    r"""``out[k] = Σ_{e : index[e] = k} x[e]`` along dimension 0.

    The same sums, in the same order, as PyG's ``SumAggregation`` (``scatter_add_`` with the
    index broadcast to ``x``'s shape), so the results are bit-equal; ``index_add_`` adds whole
    rows, and its backward is a row gather (``index_select``) instead of an element-wise
    ``gather``: about 2× faster forward and backward together on the CPU (docs/PERFORMANCE.md).

    Shapes: ``x [E, h]``, ``index [E]`` → ``[dim_size, h]``.
    """

    def forward(
        self,
        x: Tensor,
        index: Tensor | None = None,
        ptr: Tensor | None = None,
        dim_size: int | None = None,
        dim: int = -2,
    ) -> Tensor:
        if index is None or dim not in (0, -2) or x.dim() != 2:
            raise ValueError("IndexSum sums rows of a [E, h] tensor by an index [E]")
        return x.new_zeros(dim_size, x.shape[1]).index_add_(0, index, x)


def inverse_degree(index: Tensor, num_nodes: int, like: Tensor) -> Tensor:
    r"""``[N, 1]``: :math:`1 / \max(1, d_k)`, :math:`d_k = |\{e : \mathrm{index}[e] = k\}|` the
    in-degree of node k, in ``like``'s dtype and device (counted by ``index_add_``: nothing is
    read back). Multiplied into an :class:`IndexSum` it gives the *mean* of the incoming
    messages, which stays within the messages' own range however many contacts a sphere has
    (a sum of 12 similar messages is 12 times one).

    Shapes: ``index [E]`` → ``[num_nodes, 1]``.
    """
    ones = like.new_ones(index.shape[0])
    degree = like.new_zeros(num_nodes).index_add_(0, index, ones)
    return degree.clamp_min(1.0).reciprocal()[:, None]
