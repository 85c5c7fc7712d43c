"""What differs between two graphs' network inputs, and the spheres the change can reach.

Two passes of a network over the same nodes (a pass and its rebuild, :mod:`physgnn.nn.reuse`)
see inputs that differ in a few places: edges the second graph adds (or lacks), and rows of
node or edge features that are not the same. Edges are matched by their endpoints (pp by the
pair ``(j, i)`` of the first half of the paired layout, ps by ``(plane, sphere)``), rows
compared exactly (a NaN counts as changed), so the changed set does not depend on *why* the
inputs differ (:func:`changes`).

Which latents differ: with ``V_0`` the nodes whose input row differs (their encoded latent
does) and ``S`` the endpoints of pp pairs and the spheres of ps edges that are new, gone or whose
input row differs (their messages, degrees and edge latents do), a node's latent after block 1
can differ only in the *seed* ``T_1 = N[V_0] ∪ S`` (``N[·]``: the set and its pp neighbours),
and after block ``k`` only in ``T_k = N^{k-1}[T_1]``: a block spreads a difference by one pp
hop, and the pp edge latents that differ join nodes of ``T_k`` only. :func:`hops` gives the
``T_k``; a ps edge joins no two spheres (planes hold no latent), so only pp edges spread a
change.

Shapes (N nodes; E, E' pp edges and F, F' ps edges of the new and the earlier graph):
``pp_index [2, E]`` in the paired layout (edge ``e + E/2`` is the reverse of edge ``e``),
``ps_index [2, F]`` (row 0 the plane, row 1 the sphere).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor


@dataclass(frozen=True)
class Changes:
    """``pair_old [E/2]``, ``ps_old [F]`` (long): the earlier graph's row of each pair / ps
    edge (any valid row where it has none); ``pair_changed [E/2]``, ``ps_changed [F]``,
    ``node_changed [N]`` (bool): rows that are new or whose inputs differ; ``seed [N]`` (bool):
    ``T_1``, the nodes whose latent may differ after the first block (module doc)."""

    pair_old: Tensor
    pair_changed: Tensor
    ps_old: Tensor
    ps_changed: Tensor
    node_changed: Tensor
    seed: Tensor


def matched(old_keys: Tensor, new_keys: Tensor) -> tuple[Tensor, Tensor]:
    """``(row [K], found [K])``: for each of ``new_keys [K]``, a row of ``old_keys [K']`` (int64,
    unique) holding the same key where ``found`` (else any valid row; 0 when ``K' = 0``)."""
    if old_keys.shape[0] == 0:
        return torch.zeros_like(new_keys), torch.zeros_like(new_keys, dtype=torch.bool)
    ordered, order = torch.sort(old_keys)
    at = torch.searchsorted(ordered, new_keys).clamp_max(old_keys.shape[0] - 1)
    return order[at], ordered[at] == new_keys


def differs(new: Tensor, old: Tensor, row: Tensor) -> Tensor:
    """``[K]`` bool: row k of ``new [K, d]`` is not exactly row ``row[k]`` of ``old [K', d]``
    (a NaN differs; every row differs when ``K' = 0``)."""
    if old.shape[0] == 0:
        return torch.ones(new.shape[0], dtype=torch.bool, device=new.device)
    return (new != old[row]).any(1)


def changes(earlier, x, pp_index, pp_attr, ps_index, ps_attr, material=None) -> Changes:
    """The :class:`Changes` from ``earlier`` (anything with the fields ``x``, ``pp_index``,
    ``pp_attr``, ``ps_index``, ``ps_attr``, ``material``: the earlier pass's inputs, the same N
    nodes) to these inputs (module doc)."""
    n = x.shape[0]
    node_changed = (x != earlier.x).any(1)
    if material is not None:
        node_changed = node_changed | (material != earlier.material)
    seed = torch.zeros(n, dtype=torch.int32, device=x.device)  # S, counted: no read-back
    pair_old, pair_changed = _pp_changes(earlier, pp_index, pp_attr, n, seed)
    old_planes, old_spheres = earlier.ps_index
    ps_keys, old_ps_keys = ps_index[0] * n + ps_index[1], old_planes * n + old_spheres
    ps_old, found = matched(old_ps_keys, ps_keys)
    ps_changed = ~found | differs(ps_attr, earlier.ps_attr, ps_old)
    gone = ~matched(ps_keys, old_ps_keys)[1]
    seed.index_add_(0, ps_index[1], ps_changed.to(torch.int32))
    seed.index_add_(0, old_spheres, gone.to(torch.int32))
    seed = (seed > 0) | hops(node_changed, pp_index, 1)[1]  # S ∪ N[V_0]
    return Changes(pair_old, pair_changed, ps_old, ps_changed, node_changed, seed)


def _pp_changes(earlier, pp_index, pp_attr, n: int, seed: Tensor) -> tuple[Tensor, Tensor]:
    """``(pair_old [E/2], pair_changed [E/2])`` of :class:`Changes`; the endpoints of changed
    and of gone pairs counted in ``seed [N]`` (int32, in place)."""
    half, old_half = pp_index.shape[1] // 2, earlier.pp_index.shape[1] // 2
    keys = pp_index[0, :half] * n + pp_index[1, :half]
    old_keys = earlier.pp_index[0, :old_half] * n + earlier.pp_index[1, :old_half]
    pair_old, found = matched(old_keys, keys)
    reverse = pair_old + old_half  # the earlier graph's reverse edge of each pair
    changed = differs(pp_attr[:half], earlier.pp_attr, pair_old)
    changed = ~found | changed | differs(pp_attr[half:], earlier.pp_attr, reverse)
    gone = ~matched(keys, old_keys)[1]
    for index, pairs in ((pp_index, changed), (earlier.pp_index, gone)):
        seed.index_add_(0, index[0, : pairs.shape[0]], pairs.to(torch.int32))
        seed.index_add_(0, index[1, : pairs.shape[0]], pairs.to(torch.int32))
    return pair_old, changed


def hops(seed: Tensor, pp_index: Tensor, k: int) -> list[Tensor]:
    """``[D_0, …, D_k]``, each ``[N]`` bool: ``D_0 = seed``, ``D_{j+1}`` = ``D_j`` and every node
    with a pp edge from ``D_j`` (both directions are edges in the paired layout)."""
    src, dst = pp_index
    reached = [seed]
    for _ in range(k):
        last = reached[-1]
        spread = torch.zeros(seed.shape[0], dtype=torch.int32, device=seed.device)
        spread.index_add_(0, dst, last[src].to(torch.int32))
        reached.append(last | (spread > 0))
    return reached
