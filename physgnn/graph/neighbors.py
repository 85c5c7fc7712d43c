"""Fixed-radius neighbour search that never drops a neighbour.

:func:`radius_pairs` returns every unordered pair ``(i, j)``, ``i < j``, of points of the same
scene with ``|p_i − p_j| ≤ r``. Every backend only *proposes* candidates (with a safety
margin) and the same exact test decides; the rule at the boundary is therefore identical for
all backends:

    a pair is kept iff ``dx*dx + dy*dy + dz*dz <= r*r``, evaluated left to right in float64
    with ``dx = float64(x_i) − float64(x_j)`` (and so on) and ``r`` taken as a float64.

Backends: ``"torch"`` (uniform cell grid, CPU and CUDA), ``"kdtree"`` (scipy cKDTree, CPU),
``"cluster"`` (``torch_cluster.radius_graph``, optional) and ``"auto"``.

:class:`BallIndex` answers the other question, asked again and again of one set of points:
which of them lie within a per-query distance of these other points (candidates only).
"""

from __future__ import annotations

import functools
import importlib.util
import math

import numpy as np
import torch
from scipy.spatial import cKDTree

BACKENDS = ("auto", "torch", "kdtree", "cluster")

# Cell side and k-d tree query radius are inflated by this much (relative), so that float64
# rounding of the candidate search can never lose a pair that the exact test keeps.
_MARGIN = 1e-6
# A cell is at least this fraction of the scene extent: cell coordinates stay below 1e9, where
# their float64 rounding error (≈ 1e9 · 2^-52) is far below _MARGIN.
_MIN_CELL_FRACTION = 1e-9

# torch_cluster's neighbour cap: the first pass's, and its growth while a point reaches it
_CLUSTER_CAP = 64
_CLUSTER_GROWTH = 4

# The 13 cell offsets that are lexicographically positive, plus (0, 0, 0) first: each
# unordered pair of neighbouring cells is visited exactly once.
_HALF_OFFSETS = [(0, 0, 0)] + [
    (dx, dy, dz)
    for dx in (-1, 0, 1)
    for dy in (-1, 0, 1)
    for dz in (-1, 0, 1)
    if (dx, dy, dz) > (0, 0, 0)
]


def has_torch_cluster() -> bool:
    """True when ``torch_cluster`` can be imported (it is an optional extra)."""
    return importlib.util.find_spec("torch_cluster") is not None


def radius_pairs(
    pos: torch.Tensor, r: float, batch: torch.Tensor | None = None, backend: str = "auto"
) -> torch.Tensor:
    """All pairs of points of the same scene within distance ``r`` (boundary included).

    pos ``[N, 3]``, batch ``[N]`` (scene id of each point; ``None`` = one scene) →
    LongTensor ``[2, P]`` on ``pos.device`` with ``row 0 < row 1``, columns sorted
    lexicographically. No neighbour cap: a point may have any number of neighbours.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown neighbour backend '{backend}'; choose one of {list(BACKENDS)}")
    pos, batch, r = _check(pos, batch, r)
    if pos.shape[0] < 2:
        return torch.empty(2, 0, dtype=torch.long, device=pos.device)
    if backend == "auto":
        backend = _auto_backend(pos)
    if backend == "torch":
        i, j = _grid_candidates(pos, batch, r)
    elif backend == "kdtree":
        i, j = _kdtree_candidates(pos, batch, r)
    else:
        i, j = _cluster_candidates(pos, batch, r)
    return exact_pairs(pos, batch, r, i, j)


def _check(pos, batch, r) -> tuple[torch.Tensor, torch.Tensor, float]:
    if pos.dim() != 2 or pos.shape[1] != 3:
        raise ValueError(f"pos must have shape [N, 3], got {list(pos.shape)}")
    r = float(r)
    if not (r >= 0 and math.isfinite(r)):
        raise ValueError(f"radius must be finite and >= 0, got {r}")
    if not bool(torch.isfinite(pos).all()):  # a read-back: a search on NaN would lose pairs
        raise ValueError("pos contains NaN or inf")
    if batch is None:
        batch = torch.zeros(pos.shape[0], dtype=torch.long, device=pos.device)
    elif batch.shape != (pos.shape[0],):
        raise ValueError(f"batch must have shape [{pos.shape[0]}], got {list(batch.shape)}")
    return pos, batch.long(), r


def resolve_backend(backend: str, pos: torch.Tensor) -> str:
    """The backend ``backend`` names for points ``pos`` (``auto``: the k-d tree on the CPU,
    torch-cluster on CUDA when installed, else ``torch``)."""
    return _auto_backend(pos) if backend == "auto" else backend


def _auto_backend(pos: torch.Tensor) -> str:
    if pos.device.type != "cpu":
        return "cluster" if has_torch_cluster() and pos.is_cuda else "torch"
    return "kdtree"


def exact_pairs(pos, batch, r, i, j) -> torch.Tensor:
    """``[2, P]``: the candidate pairs ``(i [Q], j [Q])`` that satisfy the module's exact rule
    (same scene, distinct, centres at most ``r`` apart), oriented ``i < j``, deduplicated and
    sorted lexicographically."""
    i, j = torch.minimum(i, j), torch.maximum(i, j)
    keep = (i != j) & (batch[i] == batch[j])
    i, j = i[keep], j[keep]
    p = pos.to(torch.float64)
    d = p[i] - p[j]
    d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    keep = d2 <= r * r
    key = torch.unique(i[keep] * pos.shape[0] + j[keep])  # sorted; dedupes backends' repeats
    return torch.stack([key // pos.shape[0], key % pos.shape[0]])


# --- torch: uniform cell grid -------------------------------------------------------------


def _grid_candidates(pos, batch, r) -> tuple[torch.Tensor, torch.Tensor]:
    """Candidate pairs from a cell grid of side ≥ r: each point against 14 half-neighbourhoods."""
    cells = _cell_coords(pos, batch, r)  # [N, 3] long, compressed, ≥ 1
    size = cells.max(dim=0).values + 2
    sides = size.tolist()  # a read-back, as the search's own sizes below
    if float(sides[0]) * sides[1] * sides[2] > 2.0**62:
        raise ValueError(f"too many grid cells ({sides}) for {pos.shape[0]} points")
    key = (cells[:, 0] * size[1] + cells[:, 1]) * size[2] + cells[:, 2]
    order = torch.argsort(key)
    cell_key, inverse, cell_count = torch.unique_consecutive(
        key[order], return_inverse=True, return_counts=True
    )
    cell_start = torch.cumsum(cell_count, 0) - cell_count
    offsets = _half_offsets(pos.device)  # [14, 3]
    offset_key = (offsets[:, 0] * size[1] + offsets[:, 1]) * size[2] + offsets[:, 2]
    # Neighbour cells looked up once per occupied cell, [C, 14], then read per point, [N, 14].
    query = cell_key[:, None] + offset_key[None, :]
    found_cell = torch.searchsorted(cell_key, query).clamp_max(cell_key.numel() - 1)
    found = cell_key[found_cell] == query
    nb_start = cell_start[found_cell]
    nb_end = torch.where(found, nb_start + cell_count[found_cell], nb_start)
    cell_of = torch.empty_like(order)
    cell_of[order] = inverse
    start, end = nb_start[cell_of], nb_end[cell_of]
    # The own cell (offset 0): only partners after i in sorted order, so each pair once.
    rank = torch.empty_like(order)
    rank[order] = torch.arange(order.numel(), device=pos.device)
    start[:, 0] = rank + 1
    count = (end - start).clamp_min(0).flatten()
    slot = torch.repeat_interleave(torch.arange(count.numel(), device=pos.device), count)
    first = torch.cumsum(count, 0) - count
    local = torch.arange(slot.numel(), device=pos.device) - first[slot]
    j = order[start.flatten()[slot] + local]
    i = slot // len(_HALF_OFFSETS)
    return i, j


@functools.cache
def _half_offsets(device: torch.device) -> torch.Tensor:
    """``[14, 3]`` long: :data:`_HALF_OFFSETS` on ``device``, copied there once."""
    return torch.tensor(_HALF_OFFSETS, dtype=torch.long, device=device)


def _cell_coords(pos, batch, r) -> torch.Tensor:
    """Integer cell of each point, ``[N, 3]``; scenes separated along the first axis.

    Occupied coordinates are compressed per axis (runs of adjacent values kept, larger gaps
    shrunk to 2), which keeps neighbourhood relations and bounds each axis by 2N.
    """
    p = pos.to(torch.float64)
    lo = p.min(dim=0).values
    extent = (p.max(dim=0).values - lo).max()
    side = (extent * _MIN_CELL_FRACTION).clamp_min(max(r, 1e-300)) * (1 + _MARGIN)
    cells = torch.floor((p - lo) / side).long()
    span = cells[:, 0].max() + 3  # on the device: nothing read back
    cells[:, 0] += batch * span  # scenes are at least 2 cells apart on axis 0
    return torch.stack([_compress(cells[:, k]) for k in range(3)], dim=1)


def _compress(v: torch.Tensor) -> torch.Tensor:
    """Map integers to ``1 + rank`` keeping differences of 0 and 1, capping gaps at 2. ``[N]``."""
    values, inverse = torch.unique(v, return_inverse=True)
    step = torch.diff(values).clamp_max(2)
    compact = torch.cat([step.new_zeros(1), torch.cumsum(step, 0)])
    return compact[inverse] + 1


# --- scipy cKDTree ------------------------------------------------------------------------


def _kdtree_candidates(pos, batch, r) -> tuple[torch.Tensor, torch.Tensor]:
    """Candidate pairs from one cKDTree in float64, scenes shifted apart along x."""
    p = pos.detach().to("cpu", torch.float64).numpy()
    b = batch.detach().cpu().numpy()
    p = p - p.min(axis=0)
    extent = float(p.max())
    # Margin covers float64 rounding of the shifted coordinates (all below `top`).
    reach = r * (1 + _MARGIN)
    gap = extent + 2 * reach
    top = extent + gap * float(b.max())
    reach += 4 * np.finfo(np.float64).eps * top
    p[:, 0] += b * gap
    pairs = cKDTree(p).query_pairs(reach, output_type="ndarray")
    pairs = torch.as_tensor(pairs, dtype=torch.long, device=pos.device).reshape(-1, 2)
    return pairs[:, 0], pairs[:, 1]


# --- torch_cluster --------------------------------------------------------------------------


def _load_radius_graph():
    """``torch_cluster.radius_graph``, imported when first asked for (an optional extra)."""
    if not has_torch_cluster():
        raise ValueError("neighbour backend 'cluster' needs torch_cluster, which is not installed")
    from torch_cluster import radius_graph

    return radius_graph


def _cluster_candidates(pos, batch, r) -> tuple[torch.Tensor, torch.Tensor]:
    """Candidate pairs from ``torch_cluster.radius_graph`` with a bounded neighbour cap.

    The CUDA kernel allocates ``16 · N · cap`` bytes whatever the answer (23 GB for cap = N at
    38 000 points), and keeps at most ``cap`` neighbours of each point. So the search asks for
    :data:`_CLUSTER_CAP` first; where some point reached the cap (counted on the device, one
    read-back per pass) it may have lost neighbours, and the search is repeated with a cap
    :data:`_CLUSTER_GROWTH` times larger, up to ``N − 1``, where nothing can be lost. The
    answer is exact either way; only crowded scenes pay a second pass."""
    radius_graph = _load_radius_graph()
    p = pos.to(torch.float32)
    scale = float(p.abs().max())
    reach = r * (1 + 1e-4) + 4 * float(torch.finfo(torch.float32).eps) * scale
    order = torch.argsort(batch, stable=True)  # torch_cluster needs the batch sorted
    p, b, n = p[order], batch[order], pos.shape[0]
    cap = min(_CLUSTER_CAP, n - 1)
    while True:
        edge = radius_graph(p, reach, b, loop=False, max_num_neighbors=cap)
        if cap >= n - 1:
            break
        # edge[1] is the point whose neighbours were capped; the one read-back of the pass
        if not bool((torch.bincount(edge[1], minlength=n) >= cap).any()):
            break
        cap = min(cap * _CLUSTER_GROWTH, n - 1)
    return order[edge[0]], order[edge[1]]


# --- a k-d tree kept over one set of points -------------------------------------------------


class BallIndex:
    """A cKDTree over points of a batch of scenes, for repeated queries: which of them lie
    within ``search_q`` of query point ``q`` (float64, on the CPU).

    The scene id times ``span`` is a 4th coordinate, so the tree seldom proposes pairs across
    scenes; the answer is a superset of the same-scene pairs (any ``span``): the caller
    applies the exact rule.
    """

    def __init__(self, pos: torch.Tensor, batch: torch.Tensor, span: float):
        self.span = float(span)
        self.tree = cKDTree(self._points(pos, batch))

    def _points(self, pos: torch.Tensor, batch: torch.Tensor) -> np.ndarray:
        p = pos.detach().to("cpu", torch.float64).numpy()
        b = batch.detach().cpu().numpy().astype(np.float64)
        return np.concatenate([p, (b * self.span)[:, None]], axis=1)

    def near(
        self, pos: torch.Tensor, batch: torch.Tensor, search: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(query row [P], indexed point [P])`` with centres at most ``search [Q]`` apart,
        on ``pos.device``."""
        radii = search.detach().to("cpu", torch.float64).numpy()
        hits = self.tree.query_ball_point(self._points(pos, batch), radii * (1 + 1e-9) + 1e-12)
        counts = np.fromiter((len(h) for h in hits), dtype=np.int64, count=len(hits))
        rows = np.repeat(np.arange(len(hits)), counts)
        cols = np.concatenate([np.asarray(h, dtype=np.int64) for h in hits]) if counts.sum() else []
        return _long_tensor(rows, pos.device), _long_tensor(cols, pos.device)


def _long_tensor(values, device: torch.device) -> torch.Tensor:
    """``values`` (an array or a list) as an int64 tensor on ``device``."""
    return torch.as_tensor(np.asarray(values, np.int64), device=device)


def extent_span(pos: torch.Tensor, margin: float = 0.0) -> float:
    """A ``span`` for :class:`BallIndex`: twice the extent of ``pos`` plus ``margin`` and 1 km."""
    p = pos.detach().to("cpu", torch.float64)
    return 2.0 * float((p.max(0).values - p.min(0).values).max()) + margin + 1e3
