"""GraphBuilder: hand-built scenes, a brute-force oracle, layout and invariance properties."""

from __future__ import annotations

import math

import pytest
import torch
from handmade import WALL_ROW, make_state
from torch_geometric.data import Batch

from physgnn.data.state import SceneState
from physgnn.graph.builder import Graph, GraphBuilder
from physgnn.physics.scene import GROUND, STATIC, WALL, make_plane


def pairs_of(g: Graph) -> list[tuple[int, int]]:
    half = g.pp_index[:, : g.num_pairs]
    return [tuple(c) for c in half.t().tolist()]


def ps_of(g: Graph) -> list[tuple[int, int]]:
    return [tuple(c) for c in g.ps_index.t().tolist()]


# --- hand-built pp cases --------------------------------------------------------------------


def test_epsilon_rule_edge_exactly_on_threshold():
    # radius 0.5: gap A–B = 0.25 (= ε, kept), gap B–C = 0.75.
    state = make_state([[0, 0, 5], [1.25, 0, 5], [3.0, 0, 5]])
    g = GraphBuilder("epsilon", epsilon=0.25)(state)
    torch.testing.assert_close(g.pp_index, torch.tensor([[0, 1], [1, 0]]))
    expected = torch.tensor([[1.25, 0, 0, 1.25], [-1.25, 0, 0, 1.25]])
    torch.testing.assert_close(g.pp_attr, expected)
    assert pairs_of(GraphBuilder("epsilon", epsilon=0.24)(state)) == []


def test_vi_rule_uses_both_speeds_and_factor():
    # dt = 1/8; A moves at 2 m/s, B rests, C moves at 3 m/s; gaps A–B 0.25, B–C 0.5, A–C 1.75.
    pos = [[0, 0, 5], [1.25, 0, 5], [2.75, 0, 5]]
    vel = [[2, 0, 0], [0, 0, 0], [0, 3, 0]]
    state = make_state(pos, vel)
    # thresholds: A–B 2/8 = 0.25 (exactly), B–C 3/8 < 0.5, A–C 5/8 < 1.75
    assert pairs_of(GraphBuilder("vi", epsilon=0.0)(state)) == [(0, 1)]
    # factor 2: A–B 0.5, B–C 0.75 ≥ 0.5, A–C 1.25 < 1.75
    assert pairs_of(GraphBuilder("vi", epsilon=0.0, factor=2.0)(state)) == [(0, 1), (1, 2)]
    # ε adds to the threshold: B–C needs 0.125 more
    assert pairs_of(GraphBuilder("vi", epsilon=0.125)(state)) == [(0, 1), (1, 2)]


def test_vmax_rule_uses_the_scene_maximum():
    pos = [[0, 0, 5], [1.25, 0, 5], [2.75, 0, 5]]
    vel = [[2, 0, 0], [0, 0, 0], [0, 3, 0]]
    state = make_state(pos, vel)
    # 2·V_max·dt = 0.75: A–B and B–C (gap 0.5) but not A–C (gap 1.75)
    assert pairs_of(GraphBuilder("vmax", epsilon=0.0)(state)) == [(0, 1), (1, 2)]
    # factor 0.25 → 0.1875 < 0.25: nothing; + ε 0.0625 → exactly 0.25: A–B
    assert pairs_of(GraphBuilder("vmax", epsilon=0.0, factor=0.25)(state)) == []
    assert pairs_of(GraphBuilder("vmax", epsilon=0.0625, factor=0.25)(state)) == [(0, 1)]


def test_vmax_is_per_scene_in_a_batch():
    slow = make_state([[0, 0, 5], [1.25, 0, 5]])  # gap 0.25, at rest
    fast = make_state([[0, 0, 5], [1.25, 0, 5], [50, 0, 5]], vel=[[0, 0, 0]] * 2 + [[4, 0, 0]])
    g = GraphBuilder("vmax", epsilon=0.0)(Batch.from_data_list([slow, fast]))
    assert pairs_of(g) == [(2, 3)]  # the fast sphere in scene 1 does not widen scene 0


def test_exactly_touching_and_coincident_spheres_have_finite_features_and_gradients():
    pos = torch.tensor([[0.0, 0, 5], [1.0, 0, 5], [1.0, 0, 5]], requires_grad=True)
    state = make_state(pos.detach())
    state.pos = pos
    g = GraphBuilder("epsilon", epsilon=0.0)(state)
    assert pairs_of(g) == [(0, 1), (0, 2), (1, 2)]  # touching (gap 0) and coincident
    coincident = g.pp_attr[2]
    torch.testing.assert_close(coincident, torch.zeros(4))
    assert bool(torch.isfinite(g.pp_attr).all())
    (g.pp_attr.square().sum() + g.pp_attr[:, 3].sum() + g.ps_attr.sum()).backward()
    assert bool(torch.isfinite(pos.grad).all())


def test_one_sphere_zero_speed_and_ground_only():
    g = GraphBuilder("vi", clip_margin=0.0)(make_state([[1, 2, 3]], vel=[[1, 0, 0]]))
    assert g.pp_index.shape == (2, 0) and g.pp_attr.shape == (0, 4)
    assert ps_of(g) == [(0, 0)]
    # height 3 clipped at the reach r + |v|·dt + ε = 0.5 + 0.125 + 0.01
    expected = torch.tensor([[1.0, 0, 0, 0, 0, 1, 0, 0, 0.635, 0.635]])
    torch.testing.assert_close(g.ps_attr, expected)


def test_zero_spheres_gives_empty_tensors_of_the_right_shapes():
    g = GraphBuilder()(make_state(torch.zeros(0, 3), planes=[WALL_ROW], kinds=[WALL]))
    assert g.pp_index.shape == (2, 0) and g.pp_attr.shape == (0, 4)
    assert g.ps_index.shape == (2, 0) and g.ps_attr.shape == (0, 10)


def test_zero_speed_everywhere_makes_vi_and_vmax_equal_epsilon():
    gen = torch.Generator().manual_seed(4)
    pos = torch.rand(40, 3, generator=gen) * 6
    state = make_state(pos, planes=[WALL_ROW], kinds=[WALL])
    ref = GraphBuilder("epsilon", epsilon=0.3)(state)
    for rule in ("vi", "vmax"):
        g = GraphBuilder(rule, epsilon=0.3)(state)
        torch.testing.assert_close(g.pp_index, ref.pp_index)
        torch.testing.assert_close(g.ps_index, ref.ps_index)
    assert ref.num_pairs > 0


def test_a_ground_only_scene_has_one_ground_edge_per_sphere():
    g = GraphBuilder()(make_state([[0, 0, 1], [3, 0, 40]]))
    assert ps_of(g) == [(0, 0), (0, 1)]


# --- hand-built ps cases --------------------------------------------------------------------


def test_sphere_exactly_on_a_wall_on_its_edge_and_on_its_corner():
    pos = [
        [3.5, 0, 3],  # touches the face (distance 0.5 = r)
        [4, 2.5, 3],  # in the wall's plane, 0.5 beyond its y edge
        [4, 5, 10],  # beyond the corner (y 2, z 6) by (3, 4): distance 5 = r
        [3.5, 2.5, 3],  # diagonal to the edge: distance √0.5 > r
        [2.5, 0, 3],  # 0.5 clear of the face
    ]
    radius = torch.tensor([0.5, 0.5, 5.0, 0.5, 0.5])
    state = make_state(pos, radius=radius, planes=[WALL_ROW], kinds=[WALL])
    g = GraphBuilder("epsilon", epsilon=0.0)(state)
    assert [e for e in ps_of(g) if e[0] == 1] == [(1, 0), (1, 1), (1, 2)]
    # sphere 3 joins once ε covers √0.5 − 0.5 ≈ 0.2071
    g = GraphBuilder("epsilon", epsilon=0.21)(state)
    assert [e for e in ps_of(g) if e[0] == 1] == [(1, 0), (1, 1), (1, 2), (1, 3)]
    shrunk = make_state(pos, radius=radius * 0.999, planes=[WALL_ROW], kinds=[WALL])
    assert [e for e in ps_of(GraphBuilder("epsilon", epsilon=0.0)(shrunk)) if e[0] == 1] == []


def test_ps_features_by_hand():
    state = make_state([[3.5, 0, 3]], vel=[[1, 0, 0]], planes=[WALL_ROW], kinds=[WALL])
    g = GraphBuilder("epsilon", epsilon=0.0, clip_margin=0.0)(state)
    assert ps_of(g) == [(0, 0), (1, 0)]
    ground = [1, 0, 0, 0, 0, 1, 0, 0, 0.5, 0.5]  # height 3 clipped at the reach r = 0.5
    # wall: n = (−1, 0, 0), (p − p_s)·n = 0.5, so ((p − p_s)·n) n = (−0.5, 0, 0)
    wall = [1, 0, 0, -1, 0, 0, -0.5, 0, 0, 0.5]
    torch.testing.assert_close(g.ps_attr, torch.tensor([ground, wall], dtype=torch.float32))


def test_vi_ps_rule_on_threshold():
    # 0.25 clear of the wall, moving at 2 m/s, dt 1/8: reach 0.25 exactly.
    state = make_state([[3.25, 0, 3]], vel=[[0, 0, 2]], planes=[WALL_ROW], kinds=[WALL])
    assert ps_of(GraphBuilder("vi", epsilon=0.0)(state)) == [(0, 0), (1, 0)]
    assert ps_of(GraphBuilder("vi", epsilon=0.0, factor=0.5)(state)) == [(0, 0)]


def test_plane_below_a_sphere_measures_the_rectangle_not_the_infinite_plane():
    ramp = make_plane((0, 0, 2), (0, 0, 1), (1, 0, 0), 1.0, 1.0)
    state = make_state([[0, 0, 2.5], [3, 0, 2.5]], planes=[ramp], kinds=[STATIC])
    g = GraphBuilder("epsilon", epsilon=0.0)(state)
    assert ps_of(g) == [(0, 0), (0, 1), (1, 0)]


# --- effects --------------------------------------------------------------------------------


def test_disabled_effects_remove_their_edges():
    pos = [[3.5, 0, 3], [2.5, 0, 3]]  # touching each other and sphere 0 touches the wall
    full = make_state(pos, planes=[WALL_ROW], kinds=[WALL])
    g = GraphBuilder("epsilon", epsilon=0.0)(full)
    assert pairs_of(g) == [(0, 1)] and ps_of(g) == [(0, 0), (0, 1), (1, 0)]
    cases = {
        # gravity, sphere_contact, surface_contact → (pairs, ps edges)
        (True, False, True): ([], [(0, 0), (0, 1), (1, 0)]),
        (True, True, False): ([(0, 1)], [(0, 0), (0, 1)]),
        (False, True, True): ([(0, 1)], [(0, 0), (0, 1), (1, 0)]),
        (False, True, False): ([(0, 1)], []),
    }
    for (gravity, spheres, surfaces), (pairs, ps) in cases.items():
        effects = [gravity, spheres, surfaces, True, True]
        state = make_state(pos, planes=[WALL_ROW], kinds=[WALL], effects=effects)
        g = GraphBuilder("epsilon", epsilon=0.0)(state)
        assert (pairs_of(g), ps_of(g)) == (pairs, ps), effects
        assert g.pp_attr.shape == (2 * len(pairs), 4) and g.ps_attr.shape == (len(ps), 10)


def test_effects_apply_per_scene_in_a_batch():
    pos = [[3.5, 0, 3], [2.5, 0, 3]]
    on = make_state(pos, planes=[WALL_ROW], kinds=[WALL])
    off = make_state(pos, planes=[WALL_ROW], kinds=[WALL], effects=[True, False, False, True, True])
    g = GraphBuilder("epsilon", epsilon=0.0)(Batch.from_data_list([off, on]))
    assert pairs_of(g) == [(2, 3)]
    assert ps_of(g) == [(0, 0), (0, 1), (2, 2), (2, 3), (3, 2)]


def test_bad_configuration_and_missing_ground(monkeypatch):
    with pytest.raises(ValueError, match="unknown connectivity 'knn'"):
        GraphBuilder("knn")
    with pytest.raises(ValueError, match="epsilon"):
        GraphBuilder(epsilon=-1.0)
    with pytest.raises(ValueError, match="unknown neighbour backend"):
        GraphBuilder(backend="octree")
    state = make_state([[0, 0, 1]])
    state.plane_kind = torch.tensor([WALL])
    monkeypatch.setenv("PHYSGNN_CHECKS", "1")  # a check that reads back: debug only
    with pytest.raises(ValueError, match="exactly one ground plane"):
        GraphBuilder()(state)


# --- brute-force oracle and properties ------------------------------------------------------


def random_scene(gen: torch.Generator, n: int, effects=None) -> SceneState:
    """A closed box with a tilted static plane; spheres packed densely with random speeds."""
    side = 4.0
    walls = [
        make_plane((side, 0, 2), (-1, 0, 0), (0, 1, 0), side, 2),
        make_plane((-side, 0, 2), (1, 0, 0), (0, 1, 0), side, 2),
        make_plane((0, side, 2), (0, -1, 0), (1, 0, 0), side, 2),
        make_plane((0, -side, 2), (0, 1, 0), (1, 0, 0), side, 2),
        make_plane((1, 1, 2), (0.3, 0.1, 1.0), (1.0, 0, -0.3), 2.0, 1.5),
    ]
    pos = (torch.rand(n, 3, generator=gen) * 2 - 1) * side
    pos[:, 2] = pos[:, 2].abs() * 0.6
    vel = torch.randn(n, 3, generator=gen) * 3
    radius = 0.2 + 0.4 * torch.rand(n, generator=gen)
    dt = 0.05 + 0.1 * float(torch.rand((), generator=gen))
    kinds = [WALL] * 4 + [STATIC]
    return make_state(pos, vel, radius, walls, kinds, dt, effects)


def brute_force(state: Batch, rule: str, eps: float, factor: float):
    """Edges by loops over all pairs and all (plane, sphere) pairs, float64."""
    p = state.pos.double()
    v = state.vel[:, 0].double().norm(dim=-1)
    r, b = state.radius.double(), state.batch
    dt = state.dt.double()
    vmax = [float(v[b == k].max()) if bool((b == k).any()) else 0.0 for k in range(len(dt))]

    def allowance(i):
        speed = {"epsilon": 0.0, "vi": float(v[i]), "vmax": vmax[b[i]]}[rule]
        return factor * speed * float(dt[b[i]])

    n = len(p)
    pairs = []
    for i in range(n):
        for j in range(i + 1, n):
            if b[i] != b[j] or not state.effects[b[i], 1]:
                continue
            gap = float((p[i] - p[j]).norm()) - float(r[i]) - float(r[j])
            if gap <= allowance(i) + allowance(j) + eps:
                pairs.append((i, j))
    ps = []
    for s, row in enumerate(state.planes.double()):
        scene = int(state.plane_batch[s])
        for i in torch.nonzero(b == scene).flatten().tolist():
            grav, surf = bool(state.effects[scene, 0]), bool(state.effects[scene, 2])
            if int(state.plane_kind[s]) == GROUND:
                if grav or surf:
                    ps.append((s, i))
                continue
            c, nrm, d = row[:3], row[3:6], row[6:9]
            e = torch.linalg.cross(nrm, d)
            rel = p[i] - c
            u = min(max(float(rel @ d), -float(row[9])), float(row[9]))
            w = min(max(float(rel @ e), -float(row[10])), float(row[10]))
            closest = c + u * d + w * e
            behind = float(rel @ nrm) <= -float(r[i])  # planes are one-sided
            near = float((p[i] - closest).norm()) - float(r[i]) <= allowance(i) + eps
            if surf and near and not behind:
                ps.append((s, i))
    return pairs, sorted(ps)


@pytest.mark.parametrize("rule", ["epsilon", "vmax", "vi"])
def test_random_batched_scenes_match_brute_force(rule):
    gen = torch.Generator().manual_seed(5)
    effects = [None, None, [True, False, True, True, True], [False, True, False, True, True]]
    scenes = [random_scene(gen, n, fx) for n, fx in zip((30, 1, 25, 20), effects, strict=True)]
    state = Batch.from_data_list(scenes)
    for eps, factor in ((0.1, 1.0), (0.0, 0.5)):
        g = GraphBuilder(rule, epsilon=eps, factor=factor, backend="torch")(state)
        pairs, ps = brute_force(state, rule, eps, factor)
        assert pairs_of(g) == pairs
        assert ps_of(g) == ps
        assert len(pairs) >= 5 and len(ps) > 56 + 10  # 56 ground edges + walls
        g2 = GraphBuilder(rule, epsilon=eps, factor=factor, backend="kdtree")(state)
        torch.testing.assert_close(g2.pp_index, g.pp_index)


def check_features(state: Batch, g: Graph, eps: float) -> None:
    """Oracle for the vi features: pp offsets; ps offsets from the closest point of the plane
    (one row at a time), clipped at the reach r + |v|·dt + ε."""
    p, v = state.pos, state.vel[:, 0]
    j, i = g.pp_index
    torch.testing.assert_close(g.pp_attr[:, :3], p[i] - p[j])
    torch.testing.assert_close(g.pp_attr[:, 3], (p[i] - p[j]).norm(dim=-1))
    rows = []
    for s, k in g.ps_index.T.tolist():
        row = state.planes[s].double()
        c, nrm, d = row[:3], row[3:6], row[6:9]
        rel = p[k].double() - c
        u = (rel @ d).clamp(-row[9], row[9]) if row[9] < math.inf else rel @ d
        w = (rel @ torch.linalg.cross(nrm, d)).clamp(-row[10], row[10])
        offset = rel - u * d - w * torch.linalg.cross(nrm, d)
        reach = float(state.radius[k]) + float(v[k].norm()) * float(state.dt[state.batch[k]]) + eps
        offset = offset * min(1.0, reach / float(offset.norm()))
        rows.append(torch.cat([v[k].double(), nrm, offset, (offset @ nrm)[None]]))
    torch.testing.assert_close(g.ps_attr, torch.stack(rows).float())


def test_paired_layout_and_features():
    gen = torch.Generator().manual_seed(6)
    state = Batch.from_data_list([random_scene(gen, 40), random_scene(gen, 30)])
    g = GraphBuilder("vi", epsilon=0.1, clip_margin=0.0)(state)
    half = g.num_pairs
    assert g.pp_index.shape[1] == 2 * half and half > 10
    torch.testing.assert_close(g.pp_index[:, half:], g.pp_index[:, :half].flip(0))
    assert bool((g.pp_index[0, :half] < g.pp_index[1, :half]).all())
    assert torch.equal(g.pp_attr[half:, :3], -g.pp_attr[:half, :3])
    assert torch.equal(g.pp_attr[half:, 3], g.pp_attr[:half, 3])
    check_features(state, g, eps=0.1)


def test_batched_graph_is_the_concatenation_of_scene_graphs():
    gen = torch.Generator().manual_seed(7)
    scenes = [random_scene(gen, n) for n in (25, 1, 30)]
    builder = GraphBuilder("vi", epsilon=0.05)
    g = builder(Batch.from_data_list(scenes))
    node_off = plane_off = 0
    pp, pp_attr, ps, ps_attr = [], [], [], []
    for scene in scenes:
        one = builder(scene)
        pp.append(one.pp_index[:, : one.num_pairs] + node_off)
        pp_attr.append(one.pp_attr[: one.num_pairs])
        ps.append(one.ps_index + torch.tensor([[plane_off], [node_off]]))
        ps_attr.append(one.ps_attr)
        node_off += scene.pos.shape[0]
        plane_off += scene.planes.shape[0]
    torch.testing.assert_close(g.pp_index[:, : g.num_pairs], torch.cat(pp, 1))
    torch.testing.assert_close(g.pp_attr[: g.num_pairs], torch.cat(pp_attr))
    torch.testing.assert_close(g.ps_index, torch.cat(ps, 1))
    torch.testing.assert_close(g.ps_attr, torch.cat(ps_attr))


def test_translation_invariance():
    gen = torch.Generator().manual_seed(8)
    state = random_scene(gen, 40)
    # dyadic coordinates so that the translation is exact and so are the edge decisions
    state.pos = torch.round(state.pos * 16) / 16
    shift = torch.tensor([8.0, -4.0, 2.0])
    moved = state.clone()
    moved.pos = state.pos + shift
    moved.planes = state.planes.clone()
    moved.planes[:, :3] += shift
    builder = GraphBuilder("vi", epsilon=0.1)
    a, b = builder(state), builder(moved)
    for key in ("pp_index", "pp_attr", "ps_index", "ps_attr"):
        torch.testing.assert_close(getattr(a, key), getattr(b, key))
    assert a.num_pairs > 0


def test_history_velocity_uses_the_latest_frame_and_builder_from_a_mapping():
    state = make_state([[3.25, 0, 3]], planes=[WALL_ROW], kinds=[WALL])
    state.vel = torch.tensor([[[0.0, 0, 2], [0, 0, 0], [0, 0, 0]]])  # H = 2, latest first
    g = GraphBuilder(**{"connectivity": "vi", "epsilon": 0.0})(state)
    assert ps_of(g) == [(0, 0), (1, 0)]
    torch.testing.assert_close(g.ps_attr[:, :3], torch.tensor([[0.0, 0, 2], [0, 0, 2]]))


def test_float64_state_gives_the_same_graph():
    gen = torch.Generator().manual_seed(10)
    state = Batch.from_data_list([random_scene(gen, 30), random_scene(gen, 12)])
    double = state.clone()
    for key in ("pos", "vel", "radius", "planes", "dt"):
        setattr(double, key, getattr(state, key).double())
    builder = GraphBuilder("vi", epsilon=0.05)
    a, b = builder(state), builder(double)
    assert b.pp_attr.dtype == b.ps_attr.dtype == torch.float64
    torch.testing.assert_close(a.pp_index, b.pp_index)
    torch.testing.assert_close(a.ps_index, b.ps_index)
    torch.testing.assert_close(a.pp_attr.double(), b.pp_attr)
    torch.testing.assert_close(a.ps_attr.double(), b.ps_attr)


def box_lattice_state(nx: int, ny: int, nz: int) -> SceneState:
    axes = [torch.arange(k, dtype=torch.float32) for k in (nx, ny, nz)]
    pos = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    pos[:, 2] += 0.5  # unit spheres (radius 0.5) resting on the ground, all touching
    walls = [make_plane((-0.5, 0, 0), (1, 0, 0), (0, 1, 0), 100, 100)]
    return make_state(pos, radius=0.5, planes=walls, kinds=[WALL])


@pytest.mark.parametrize("backend", ["torch", "kdtree"])
def test_tight_pack_of_10000_spheres(backend):
    nx, ny, nz = 25, 20, 20
    state = box_lattice_state(nx, ny, nz)
    g = GraphBuilder("vi", epsilon=0.01, backend=backend, clip_margin=0.0)(state)
    touching = (nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)
    assert g.num_pairs == touching
    assert g.ps_index.shape[1] == 10_000 + ny * nz  # every ground edge + the x = 0 layer
    torch.testing.assert_close(g.pp_attr[:, 3], torch.ones(2 * touching))
    # heights above the ground are clipped at the reach r + ε (no absolute altitude)
    assert math.isclose(float(g.ps_attr[:, 9].max()), 0.51, rel_tol=1e-6)


# --- no absolute position in the features ---------------------------------------------------


@pytest.mark.parametrize("height", [10.0, 100.0, 1000.0])
def test_ground_edge_of_a_sphere_in_free_flight_is_the_same_at_any_height(height):
    low = GraphBuilder()(make_state([[0, 0, 5.0]], vel=[[0.3, 0, -2.0]]))
    high = GraphBuilder()(make_state([[0, 0, height]], vel=[[0.3, 0, -2.0]]))
    torch.testing.assert_close(high.ps_index, low.ps_index)
    torch.testing.assert_close(high.ps_attr, low.ps_attr)


def test_sphere_beside_a_bounded_plane_gets_no_plane_edge():
    ramp = make_plane((0, 0, 2), (0, 0, 1), (1, 0, 0), 1.0, 1.0)  # 2 m x 2 m, facing up
    beside = make_state([[1.8, 0, 2.2]], planes=[ramp], kinds=[STATIC])  # past its edge
    above = make_state([[0.5, 0, 2.4]], planes=[ramp], kinds=[STATIC])
    assert ps_of(GraphBuilder(epsilon=0.1)(beside)) == [(0, 0)]  # the ground only
    assert ps_of(GraphBuilder(epsilon=0.1)(above)) == [(0, 0), (1, 0)]


def test_planes_are_one_sided():
    wall = make_plane((0, 0, 2), (1, 0, 0), (0, 1, 0), 5.0, 5.0)  # faces +x
    front = make_state([[0.55, 0, 2]], planes=[wall], kinds=[WALL])
    touching_behind = make_state([[-0.3, 0, 2]], planes=[wall], kinds=[WALL])
    through = make_state([[-0.55, 0, 2]], planes=[wall], kinds=[WALL])
    builder = GraphBuilder(epsilon=0.1)
    assert ps_of(builder(front)) == [(0, 0), (1, 0)]
    g = builder(touching_behind)
    assert ps_of(g) == [(0, 0), (1, 0)]
    torch.testing.assert_close(g.ps_attr[1, 6:], torch.tensor([-0.3, 0, 0, -0.3]))
    assert ps_of(builder(through)) == [(0, 0)]  # tunnelled: the wall does not push it back


def test_clip_margin_separates_resting_from_falling_and_keeps_heights_out():
    builder = GraphBuilder("vi", epsilon=0.01, clip_margin=1.0)
    resting = builder(make_state([[0, 0, 0.5]]))
    hovering = builder(make_state([[0, 0, 0.52]]))
    assert float(resting.ps_attr[0, 9]) == pytest.approx(0.5)
    assert float(hovering.ps_attr[0, 9]) == pytest.approx(0.52)  # within the margin: exact
    far = [builder(make_state([[0, 0, h]])).ps_attr for h in (10.0, 100.0, 1000.0)]
    assert float(far[0][0, 9]) == pytest.approx(1.51)  # r + ε + margin
    torch.testing.assert_close(far[1], far[0])
    torch.testing.assert_close(far[2], far[0])
