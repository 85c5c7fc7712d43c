"""radius_pairs against brute force on random and adversarial inputs, for every backend.

Oracle rule (the module's, stated there): a pair (i < j) of one scene is a neighbour pair iff
``dx*dx + dy*dy + dz*dz <= r*r`` in float64, from the float64 casts of the coordinates.
"""

from __future__ import annotations

import pytest
import torch

from physgnn.graph import neighbors
from physgnn.graph.neighbors import has_torch_cluster, radius_pairs

BACKENDS = ["torch", "kdtree", "auto"] + (["cluster"] if has_torch_cluster() else [])
needs_cluster = pytest.mark.skipif(not has_torch_cluster(), reason="torch_cluster not installed")


def brute_pairs(pos: torch.Tensor, r: float, batch: torch.Tensor | None = None) -> torch.Tensor:
    """All pairs by the float64 rule, ``[2, P]`` sorted (triu order is lexicographic)."""
    n = pos.shape[0]
    batch = torch.zeros(n, dtype=torch.long) if batch is None else batch
    i, j = torch.triu_indices(n, n, 1)
    p = pos.double()
    d = p[i] - p[j]
    d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    keep = (d2 <= r * r) & (batch[i] == batch[j])
    return torch.stack([i[keep], j[keep]])


def box_lattice(nx: int, ny: int, nz: int, spacing: float = 1.0) -> torch.Tensor:
    """Lattice of nx·ny·nz points, ``[nx·ny·nz, 3]`` float32, x slowest."""
    axes = [torch.arange(n, dtype=torch.float32) * spacing for n in (nx, ny, nz)]
    return torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def lattice(n: int, spacing: float = 1.0) -> torch.Tensor:
    """Cubic lattice of n³ points, ``[n³, 3]`` float32."""
    return box_lattice(n, n, n, spacing)


@pytest.mark.parametrize("backend", BACKENDS)
def test_random_batched_scenes_match_brute_force(backend):
    gen = torch.Generator().manual_seed(0)
    for _ in range(8):
        n = int(torch.randint(2, 200, (), generator=gen))
        scale = float(torch.rand((), generator=gen)) * 10 + 0.1
        pos = torch.rand(n, 3, generator=gen) * scale - scale / 2
        batch = torch.sort(torch.randint(0, 4, (n,), generator=gen)).values
        r = float(torch.rand((), generator=gen)) * scale / 3
        torch.testing.assert_close(radius_pairs(pos, r, batch, backend), brute_pairs(pos, r, batch))


@pytest.mark.parametrize("backend", BACKENDS)
def test_unsorted_batch_vector(backend):
    gen = torch.Generator().manual_seed(1)
    pos = torch.rand(80, 3, generator=gen)
    batch = torch.randint(0, 3, (80,), generator=gen)
    torch.testing.assert_close(radius_pairs(pos, 0.3, batch, backend), brute_pairs(pos, 0.3, batch))


def test_random_agrees_with_cdist():
    gen = torch.Generator().manual_seed(2)
    pos = torch.randn(300, 3, generator=gen)
    dist = torch.cdist(pos.double(), pos.double(), compute_mode="donot_use_mm_for_euclid_dist")
    i, j = torch.nonzero(torch.triu(dist <= 0.5, diagonal=1), as_tuple=True)
    for backend in BACKENDS:
        torch.testing.assert_close(radius_pairs(pos, 0.5, backend=backend), torch.stack([i, j]))


@pytest.mark.parametrize("backend", BACKENDS)
def test_empty_single_and_zero_radius(backend):
    assert radius_pairs(torch.zeros(0, 3), 1.0, backend=backend).shape == (2, 0)
    assert radius_pairs(torch.zeros(1, 3), 1.0, backend=backend).shape == (2, 0)
    pos = torch.tensor([[0.0, 0, 0], [0, 0, 0], [1e-7, 0, 0], [5, 5, 5]])
    expected = torch.tensor([[0], [1]])
    torch.testing.assert_close(radius_pairs(pos, 0.0, backend=backend), expected)


@pytest.mark.parametrize("backend", BACKENDS)
def test_coincident_points_all_connect(backend):
    pos = torch.full((50, 3), 3.25)
    pairs = radius_pairs(pos, 0.0, backend=backend)
    assert pairs.shape == (2, 50 * 49 // 2)
    torch.testing.assert_close(pairs, brute_pairs(pos, 0.0))


@pytest.mark.parametrize("backend", BACKENDS)
def test_exact_distance_r_is_included(backend):
    # Lattice points at exactly r (integers are exact in float32 and float64).
    n = 6
    pos = lattice(n)
    pairs = radius_pairs(pos, 1.0, backend=backend)
    assert pairs.shape[1] == 3 * n * n * (n - 1)  # the 6-neighbourhood, each pair once
    for r in (2.0, 3.0, 2.0**0.5):
        torch.testing.assert_close(radius_pairs(pos, r, backend=backend), brute_pairs(pos, r))


@pytest.mark.parametrize("backend", BACKENDS)
def test_inexact_lattice_follows_the_float64_rule(backend):
    # Spacing 0.1 is not representable: neighbours lie a few ulps either side of r.
    pos = lattice(8, 0.1) + 0.05
    for r in (0.1, 0.2, 0.1 * 2**0.5):
        torch.testing.assert_close(radius_pairs(pos, r, backend=backend), brute_pairs(pos, r))


@pytest.mark.parametrize("backend", BACKENDS)
def test_scenes_with_identical_coordinates_do_not_connect(backend):
    one = lattice(3)
    scenes = 40
    pos = one.repeat(scenes, 1)
    batch = torch.arange(scenes).repeat_interleave(27)
    pairs = radius_pairs(pos, 1.0, batch, backend)
    torch.testing.assert_close(pairs, brute_pairs(pos, 1.0, batch))
    assert bool((batch[pairs[0]] == batch[pairs[1]]).all())
    assert pairs.shape[1] == scenes * 54


@pytest.mark.parametrize("backend", BACKENDS)
def test_huge_coordinates(backend):
    gen = torch.Generator().manual_seed(3)
    base = torch.rand(60, 3, generator=gen) * 4
    for offset in (1e6, -3e7):
        pos = base + offset  # float32 spacing ≈ 0.06 / 2: many points round together
        torch.testing.assert_close(radius_pairs(pos, 1.0, backend=backend), brute_pairs(pos, 1.0))
    # Coordinates near the float32 limit with a tiny radius: only coincident points pair up.
    pos = torch.tensor([[1e30, 0, 0], [1e30, 0, 0], [-1e30, 1e30, 0], [0, 0, 0], [0.5, 0, 0]])
    torch.testing.assert_close(
        radius_pairs(pos, 0.5, backend=backend), torch.tensor([[0, 3], [1, 4]])
    )


@pytest.mark.parametrize("backend", ["torch", "kdtree"])
def test_tight_pack_10000_counts_analytically(backend):
    nx, ny, nz = 25, 20, 20
    pos = box_lattice(nx, ny, nz)
    assert pos.shape[0] == 10_000
    pairs = radius_pairs(pos, 1.0, backend=backend)  # touching unit spheres: gap exactly 0
    expected = (nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)
    assert pairs.shape[1] == expected
    # r = fl(√2): fl(√2)² > 2 in float64, so the face diagonals (d² = 2 exactly) are in.
    diag = radius_pairs(pos, 2.0**0.5, backend=backend)
    faces = 2 * ((nx - 1) * (ny - 1) * nz + (nx - 1) * ny * (nz - 1) + nx * (ny - 1) * (nz - 1))
    assert (2.0**0.5) ** 2 > 2.0
    assert diag.shape[1] == expected + faces


def test_unknown_backend_and_bad_input():
    with pytest.raises(ValueError, match="unknown neighbour backend 'octree'"):
        radius_pairs(torch.zeros(3, 3), 1.0, backend="octree")
    with pytest.raises(ValueError, match="NaN or inf"):
        radius_pairs(torch.tensor([[0.0, float("nan"), 0]]), 1.0)
    with pytest.raises(ValueError, match="radius"):
        radius_pairs(torch.zeros(3, 3), -1.0)
    with pytest.raises(ValueError, match=r"shape \[N, 3\]"):
        radius_pairs(torch.zeros(3, 2), 1.0)


@pytest.mark.skipif(has_torch_cluster(), reason="torch_cluster is installed")
def test_cluster_backend_absent_is_one_clear_error():
    with pytest.raises(ValueError, match="needs torch_cluster"):
        radius_pairs(torch.zeros(3, 3), 1.0, backend="cluster")


@needs_cluster
def test_cluster_backend_never_drops_neighbours():
    pos = torch.zeros(100, 3)  # 99 neighbours each: far above PyG's default cap of 32
    assert radius_pairs(pos, 0.1, backend="cluster").shape[1] == 100 * 99 // 2


class CappedRadiusGraph:
    """``torch_cluster.radius_graph`` as its CUDA kernel answers, by brute force: each point
    keeps the first ``max_num_neighbors + 1`` points of its scene (itself included, index
    order) strictly within ``r``, then loops are dropped; ``[2, E]`` = (neighbour, point).
    ``caps`` records the cap of every call."""

    def __init__(self):
        self.caps: list[int] = []

    def __call__(self, x, r, batch=None, loop=False, max_num_neighbors=32, **_):
        self.caps.append(max_num_neighbors)
        assert bool((batch[1:] >= batch[:-1]).all()), "torch_cluster needs the batch sorted"
        d = x.double()[:, None, :] - x.double()[None, :, :]
        within = ((d * d).sum(-1) < r * r) & (batch[:, None] == batch[None, :])
        kept = within & (within.cumsum(1) <= max_num_neighbors + (0 if loop else 1))
        point, neighbour = kept.nonzero().T
        edge = torch.stack([neighbour, point])
        return edge if loop else edge[:, edge[0] != edge[1]]


@pytest.fixture
def capped_cluster(monkeypatch) -> CappedRadiusGraph:
    """The ``cluster`` backend on a stand-in for torch_cluster (not installed here)."""
    fake = CappedRadiusGraph()
    monkeypatch.setattr(neighbors, "_load_radius_graph", lambda: fake)
    return fake


def test_cluster_backend_asks_a_bounded_cap_and_loses_nothing(capped_cluster):
    gen = torch.Generator().manual_seed(5)
    pos = torch.rand(400, 3, generator=gen) * 20
    batch = torch.randint(0, 3, (400,), generator=gen)  # unsorted
    found = radius_pairs(pos, 1.5, batch, backend="cluster")
    torch.testing.assert_close(found, brute_pairs(pos, 1.5, batch))
    torch.testing.assert_close(found, radius_pairs(pos, 1.5, batch, backend="torch"))
    assert capped_cluster.caps == [64]  # sparse: one pass, 16·N·64 bytes, not 16·N²


def crowded(n_pile: int, n_sparse: int, gen) -> torch.Tensor:
    """``n_pile`` points in a unit cube beside ``n_sparse`` spread over a 60 m one."""
    pile = torch.rand(n_pile, 3, generator=gen)
    return torch.cat([pile, torch.rand(n_sparse, 3, generator=gen) * 60 + 5])


@pytest.mark.parametrize(
    ("n_pile", "n_sparse", "r", "caps"),
    [
        (70, 0, 1.8, [64, 69]),  # every point near every other: up to N - 1
        (300, 0, 1.8, [64, 256, 299]),
        (200, 1300, 0.5, [64, 256]),  # a crowded pile (up to ~100 neighbours) in a sparse scene
    ],
)
def test_cluster_backend_searches_again_where_a_point_reached_the_cap(
    capped_cluster, n_pile, n_sparse, r, caps
):
    pos = crowded(n_pile, n_sparse, torch.Generator().manual_seed(n_pile))
    found = radius_pairs(pos, r, backend="cluster")
    assert capped_cluster.caps == caps  # the first pass lost neighbours: searched again
    torch.testing.assert_close(found, brute_pairs(pos, r))
    torch.testing.assert_close(found, radius_pairs(pos, r, backend="torch"))
