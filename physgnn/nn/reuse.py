r"""A pass of :class:`~physgnn.nn.epd.EncodeProcessDecode` again, computing only what changed.

A second pass over a graph that differs from the first in a few edges (a rebuild within the
frame, :mod:`physgnn.models.passes`) gives the same numbers as the first wherever its inputs
are the same within reach. With ``T_k`` the nodes whose latent may differ after ``k`` blocks
(the changes' seed spread by ``k − 1`` pp hops, :mod:`physgnn.nn.changes`), block ``k`` (from
0) computes

.. math::  v^{k+1}_i = v^k_i + \mathrm{MLP}_v([v^k_i, \mathrm{Agg}^k_i]),
           \qquad i \in T_{k+1}; \qquad v^{k+1}_i = \bar v^{k+1}_i \text{ otherwise}

(``\bar v`` the earlier pass's latent) on a subgraph: the pairs with an endpoint in
``T_{k+1}`` (every message into ``T_{k+1}``; a pair's two directions, as the third law needs),
the ps edges of ``T_{k+1}``, and their endpoints (within ``T_{k+2}``); its pp edge latents
``e^{k+1} = e^k + m^k`` are new for those pairs, the earlier pass's for the others (a pair with
neither end in ``T_{k+1}`` has the same ends and latent as before). The encoders run on the
changed rows only, the node decoder on ``T_M``, the pair decoder on the pairs touching
``T_M``; every other row is the earlier pass's. The result is the whole pass's up to
float rounding (the sums run over the same terms in another grouping).

:class:`Latents` is what a pass keeps for the next: its inputs, the node latents ``[N, h]`` and
pp edge latents ``[E, h]`` after each block, the ps latents, its outputs.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from physgnn.nn.aggregation import inverse_degree
from physgnn.nn.changes import changes, hops


@dataclass(frozen=True)
class Latents:
    """One pass (module doc): inputs ``x [N, node_in]``, ``material [N] | None``, ``pp_index
    [2, E]``, ``pp_attr [E, pp_in]``, ``ps_index [2, F]``, ``ps_attr [F, ps_in]``; ``nodes`` the
    M+1 node latents ``[N, h]`` (``nodes[0]`` encoded, ``nodes[k]`` after k blocks), ``edges``
    the M+1 pp edge latents ``[E, h]``, ``e_ps [F, h] | None``; outputs ``out [N, out_dim]`` and
    ``pairs [E/2, pair_out] | None``."""

    x: Tensor
    material: Tensor | None
    pp_index: Tensor
    pp_attr: Tensor
    ps_index: Tensor
    ps_attr: Tensor
    nodes: list
    edges: list
    e_ps: Tensor | None
    out: Tensor
    pairs: Tensor | None


def whole(net, x, pp_index, pp_attr, ps_index, ps_attr, material=None, pairs=False):
    """``(out [N, out_dim], pair_out [E/2, pair_out] | None, Latents)``: ``net.forward`` (with
    ``pairs``: ``net.forward_pairs``), the same operations, keeping its latents."""
    inputs = (x, pp_index, pp_attr, ps_index, ps_attr, material)
    net._check(*inputs)
    v, e_pp, e_ps, inv_pp, inv_ps = net.encode(*inputs)
    nodes, edges = [v], [e_pp]
    for block in net.blocks:
        v, e_pp = block(v, pp_index, e_pp, ps_index, e_ps, inv_pp, inv_ps)
        nodes.append(v)
        edges.append(e_pp)
    out = net.decoder(v)
    pair_out = _decoded_pairs(net, v, pp_index, e_pp) if pairs else None
    return out, pair_out, Latents(x, material, *inputs[1:5], nodes, edges, e_ps, out, pair_out)


def _decoded_pairs(net, v, pp_index, e_pp) -> Tensor:
    """``[E/2, pair_out]``: ``net``'s pair decoder (as in ``forward_pairs``)."""
    if net.pair_decoder is None:
        raise ValueError("pair outputs need a network built with pair_out > 0")
    if pp_index.shape[1] == 0:
        return v.new_zeros(0, net.pair_decoder.mlp.out_dim)
    return net.pair_decoder(v, pp_index, e_pp)


def again(net, earlier, x, pp_index, pp_attr, ps_index, ps_attr, material=None, pairs=False):
    """:func:`whole`'s answer, computing only what differs from ``earlier`` (a
    :class:`Latents` of ``net`` on the same N nodes; module doc). One read-back: the sizes of
    the changed sets."""
    inputs = (x, pp_index, pp_attr, ps_index, ps_attr, material)
    m, half = len(net.blocks), pp_index.shape[1] // 2
    fresh = earlier is None or x.shape != earlier.x.shape or (pairs and earlier.pairs is None)
    if fresh or m == 0:
        return whole(net, *inputs, pairs=pairs)
    net._check(*inputs)
    found = changes(earlier, *inputs)
    order, changed = _levels(found, pp_index, ps_index, m)
    old_edges = torch.cat([found.pair_old, found.pair_old + earlier.pp_index.shape[1] // 2])
    v, e_pp, e_ps = _encoded(net, earlier, inputs, found, old_edges, changed)
    inv = _inverse_degrees(net, v, pp_index, ps_index, e_ps)
    inv = tuple(None if w is None else w[order.nodes] for w in inv)  # in the levels' order
    e_ps = None if e_ps is None else (e_ps, e_ps[order.ps])
    nodes, edges = [v], [e_pp]
    for k, block in enumerate(net.blocks):
        old = (earlier.nodes[k + 1], _carried(earlier.edges[k + 1], old_edges))
        v, e_pp = _block(block, k, v, e_pp, e_ps, inv, order, old, half)
        nodes.append(v)
        edges.append(e_pp)
    rows = order.nodes[: order.node_counts[m - 1]]  # T_M
    out = earlier.out.index_copy(0, rows, net.decoder(v[rows]))
    pair_out = None
    if pairs:
        pair_out = _pairs_again(net, earlier, v, e_pp, found, order, half)
    e_ps = None if e_ps is None else e_ps[0]
    return out, pair_out, Latents(x, material, *inputs[1:5], nodes, edges, e_ps, out, pair_out)


@dataclass(frozen=True)
class Levels:
    """The nodes, pairs and ps edges by the first ``T_k`` they are in (nodes), touch (pairs) or
    whose sphere is in it (ps edges), so that each block's are a prefix: ``nodes [N]``,
    ``pairs [E/2]``, ``ps [F]`` (positions); ``node_counts`` ``|T_1|, …, |T_{M+1}|``,
    ``pair_counts`` and ``ps_counts`` those of ``T_1, …, T_M`` (host ints); ``sub_pp [2, E/2]``
    the pairs in order with their ends as ranks in ``nodes``, ``sub_ps [2, F]`` likewise
    (plane, rank of the sphere): the subgraph of block ``k`` is their first columns."""

    nodes: Tensor
    pairs: Tensor
    ps: Tensor
    node_counts: list
    pair_counts: list
    ps_counts: list
    sub_pp: Tensor
    sub_ps: Tensor


def _levels(found, pp_index: Tensor, ps_index: Tensor, m: int) -> tuple:
    """``(Levels, (changed nodes, changed pairs, changed ps edges))`` (positions) of
    ``found`` (:class:`~physgnn.nn.changes.Changes`) for M = ``m`` blocks. The one read-back of
    :func:`again`: every count at once (the rows to compute are data, as a rebuild's graph
    reads its own size back)."""
    half = pp_index.shape[1] // 2
    reached = hops(found.seed, pp_index, m)  # T_1 … T_{M+1}
    level = sum((~r).long() for r in reached)  # 0 in T_1, …, M + 1 beyond T_{M+1}
    pair_level = torch.minimum(level[pp_index[0, :half]], level[pp_index[1, :half]])
    ps_level = level[ps_index[1]]
    orders = [torch.sort(lv, stable=True).indices for lv in (level, pair_level, ps_level)]
    changed = (found.node_changed, found.pair_changed, found.ps_changed)
    counts = [_histogram(lv, m + 2).cumsum(0) for lv in (level, pair_level, ps_level)]
    counts = torch.cat([counts[0][: m + 1], counts[1][:m], counts[2][:m]])
    counts = torch.cat([counts, torch.stack([c.sum() for c in changed])]).tolist()
    nodes, pairs, ps = orders
    order = torch.arange(nodes.shape[0], device=nodes.device)
    rank = torch.empty_like(nodes).scatter_(0, nodes, order)
    sub_pp = rank[pp_index[:, pairs]]
    sub_ps = torch.stack([ps_index[0, ps], rank[ps_index[1, ps]]])
    split = (counts[: m + 1], counts[m + 1 : 2 * m + 1], counts[2 * m + 1 : 3 * m + 1])
    positions = [_compact(c, n) for c, n in zip(changed, counts[3 * m + 1 :], strict=True)]
    return Levels(nodes, pairs, ps, *split, sub_pp, sub_ps), positions


def _histogram(values: Tensor, bins: int) -> Tensor:
    """``[bins]`` long: how many of ``values`` (long, in ``[0, bins)``) are each value (an
    ``index_add_``: ``bincount`` reads its size back on a GPU)."""
    counts = torch.zeros(bins, dtype=torch.long, device=values.device)
    return counts.index_add_(0, values, torch.ones_like(values))


def _compact(mask: Tensor, count: int) -> Tensor:
    """Positions of the ``count`` True entries of ``mask [P]``, in order, ``[count]``
    (``nonzero`` with its size given: nothing read back). The twin of
    :func:`physgnn.graph.candidates.compact`, which the network may not import
    (docs/ARCHITECTURE.md, rule 5)."""
    slot = torch.where(mask, torch.cumsum(mask, 0) - 1, count)  # the rest: a spare slot
    out = torch.empty(count + 1, dtype=torch.long, device=mask.device)
    out.scatter_(0, slot, torch.arange(mask.shape[0], device=mask.device))
    return out[:count]


def _carried(old: Tensor, rows: Tensor) -> Tensor:
    """``old [K', d]`` at ``rows [K]`` (zeros ``[K, d]`` when ``K' = 0``: every row is new)."""
    return old[rows] if old.shape[0] else old.new_zeros(rows.shape[0], old.shape[1])


def _encoded(net, earlier, inputs, found, old_edges, rows) -> tuple:
    """``(v [N, h], e_pp [E, h], e_ps [F, h] | None)``: the earlier pass's encoded latents,
    the changed ``rows`` ``(nodes, pairs, ps edges)`` encoded anew."""
    x, pp_index, pp_attr, ps_index, ps_attr, material = inputs
    nodes, pairs, ps_rows = rows
    v = earlier.nodes[0]
    if nodes.shape[0]:
        own = None if material is None else material[nodes]
        v = v.index_copy(0, nodes, net.node_encoder(net._node_input(x[nodes], own)))
    e_pp = _carried(earlier.edges[0], old_edges)
    if pairs.shape[0]:
        edges = torch.cat([pairs, pairs + pp_index.shape[1] // 2])
        e_pp = e_pp.index_copy(0, edges, net.pp_encoder(pp_attr[edges]))
    e_ps = None
    if net.ps_encoder is not None and ps_index.shape[1] > 0:
        if earlier.e_ps is None:  # the earlier graph had no ps edge: every row is new
            e_ps = v.new_zeros(ps_index.shape[1], v.shape[1])
        else:
            e_ps = _carried(earlier.e_ps, found.ps_old)
        if ps_rows.shape[0]:
            e_ps = e_ps.index_copy(0, ps_rows, net.ps_encoder(ps_attr[ps_rows]))
    return v, e_pp, e_ps


def _inverse_degrees(net, v, pp_index, ps_index, e_ps) -> tuple:
    """``(inv_pp, inv_ps)`` ``[N, 1] | None`` of the whole graph, as
    :meth:`~physgnn.nn.epd.EncodeProcessDecode.encode` has them."""
    if net.aggregation != "mean":
        return None, None
    n = v.shape[0]
    inv_pp = inverse_degree(pp_index[1], n, v) if pp_index.shape[1] > 0 else None
    return inv_pp, (inverse_degree(ps_index[1], n, v) if e_ps is not None else None)


def _block(block, k: int, v, e_pp, e_ps, inv, order: Levels, old, half: int) -> tuple:
    """``(v^{k+1} [N, h], e^{k+1} [E, h])`` of ``block``, the ``k``-th (module doc): on the
    pairs touching ``T_{k+1}``, the ps edges of ``T_{k+1}`` and the nodes of ``T_{k+2}`` (the
    first of ``order``'s, :class:`Levels`); ``e_ps`` ``(e_ps [F, h], in order [F, h])`` or None,
    ``inv`` the inverse degrees in order; ``old`` the earlier pass's ``(v^{k+1}, e^{k+1})``
    (the latter in this graph's edge order)."""
    targets, reach = order.node_counts[k], order.node_counts[k + 1]
    n_pairs, n_ps = order.pair_counts[k], order.ps_counts[k]
    pairs = order.pairs[:n_pairs]
    edges = torch.cat([pairs, pairs + half])
    forward = order.sub_pp[:, :n_pairs]
    sub_pp = torch.cat([forward, forward.flip(0)], 1)
    sub_e_ps = e_ps[1][:n_ps] if e_ps is not None and n_ps else None
    inv_pp, inv_ps = (None if w is None else w[:reach] for w in inv)
    sub_v = v[order.nodes[:reach]]
    agg, e_sub = block.aggregate(
        sub_v, sub_pp, e_pp[edges], order.sub_ps[:, :n_ps], sub_e_ps, inv_pp, inv_ps
    )
    new = block.update(sub_v[:targets], None if agg is None else agg[:targets])
    v_next = old[0].index_copy(0, order.nodes[:targets], new)
    return v_next, old[1].index_copy(0, edges, e_sub)


def _pairs_again(net, earlier, v, e_pp, found, order: Levels, half: int) -> Tensor:
    """``[E/2, pair_out]``: the earlier pass's pair outputs, those of the pairs touching
    ``T_M`` decoded anew (their ends within ``T_{M+1}``)."""
    out = _carried(earlier.pairs, found.pair_old)
    n_pairs = order.pair_counts[-1]
    if not n_pairs:
        return out
    pairs = order.pairs[:n_pairs]
    forward = order.sub_pp[:, :n_pairs]
    sub_v = v[order.nodes[: order.node_counts[-1]]]
    edges = torch.cat([pairs, pairs + half])
    sub = _decoded_pairs(net, sub_v, torch.cat([forward, forward.flip(0)], 1), e_pp[edges])
    return out.index_copy(0, pairs, sub)
