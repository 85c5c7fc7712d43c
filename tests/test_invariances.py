"""The invariances of the default model, exactly, on hand-built states: contacts by approach
(a superset of every contact within the frame, against brute force), relative pair inputs
(Galilean invariance), masses as ratios (mass-scale invariance), mean aggregation (bounded in
the number of contacts), a block in free flight that stays rigid, the rest decision, and the
dense-contact layouts of the training mix."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from handmade import MATERIALS, make_state, scene
from simdata import REPORT_MODEL, learned
from torch.testing import assert_close
from truthkit import scene_cfg

from physgnn.graph.builder import GraphBuilder
from physgnn.groundtruth.families import dense_contact
from physgnn.groundtruth.layouts import OVERLAP_TOL, aggregate_positions, row_positions
from physgnn.models.learned import LearnedSimulator
from physgnn.nn.aggregation import IndexSum, inverse_degree
from physgnn.nn.epd import EncodeProcessDecode, Widths
from physgnn.physics.energy import G
from physgnn.physics.geometry import rectangle_offset
from physgnn.physics.scene import STATIC, Effects, ground_plane, make_plane
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout

DT = 0.125


def make(**kwargs) -> LearnedSimulator:
    """The default model, small and untrained (random weights)."""
    torch.manual_seed(0)
    return learned(**(dict(H=2, M=2, hidden=16) | kwargs)).eval()


def random_spheres(n: int, seed: int, side: float, speed: float, min_gap: float | None = None):
    """``(pos [n, 3], vel [n, 3], radius [n])`` float32: centres in a box of ``side`` (z above
    1), radii U(0.2, 0.5), velocities N(0, speed); with ``min_gap`` no two spheres closer."""
    rng = np.random.default_rng(seed)
    radius = rng.uniform(0.2, 0.5, n)
    pos = np.zeros((n, 3))
    for k in range(n):
        while True:
            pos[k] = rng.uniform([0, 0, 1], [side, side, 1 + side / 2])
            gap = np.linalg.norm(pos[:k] - pos[k], axis=1) - radius[:k] - radius[k]
            if min_gap is None or not np.any(gap <= min_gap):
                break
    vel = rng.normal(0, speed, (n, 3))
    return (torch.tensor(a, dtype=torch.float32) for a in (pos, vel, radius))


# ----- approach connectivity ---------------------------------------------------------------------
def touching_within_the_frame(pos, vel, radius, dt) -> torch.Tensor:
    """``[N, N]`` bool, brute force: spheres i, j (constant velocities) touch at some
    τ ∈ [0, dt], from the closest approach of the quadratic ``|d + wτ|²``, float64."""
    p, v, r = (x.to(torch.float64) for x in (pos, vel, radius))
    d = p[:, None] - p[None]  # [N, N, 3]
    w = v[:, None] - v[None]
    tau = (-(d * w).sum(-1) / (w * w).sum(-1).clamp_min(1e-300)).clamp(0.0, dt)
    closest = (d + w * tau[..., None]).norm(dim=-1)
    touch = closest <= r[:, None] + r[None]
    return touch & ~torch.eye(len(p), dtype=torch.bool)


def linked(graph, n: int) -> torch.Tensor:
    out = torch.zeros(n, n, dtype=torch.bool)
    out[graph.pp_index[0], graph.pp_index[1]] = True
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_approach_links_every_pair_that_touches_within_the_frame(seed):
    n = 150  # more than the all-pairs limit per sphere: the radius search proposes the pairs
    pos, vel, radius = random_spheres(n, seed, side=7.0, speed=4.0)
    state = make_state(pos, vel, radius, dt=DT)
    graph = GraphBuilder("approach", epsilon=0.01)(state)
    edges = linked(graph, n)
    assert torch.equal(edges, edges.T)  # both directions of every pair
    touch = touching_within_the_frame(pos, vel, radius, DT)
    assert int(touch.sum()) >= 20  # enough contacts to mean something
    assert not (touch & ~edges).any(), (touch & ~edges).nonzero()[:5].tolist()
    # and no looser than the bound |v_i − v_j| dt + ε that it refines
    p, v, r = (x.to(torch.float64) for x in (pos, vel, radius))
    gap = (p[:, None] - p[None]).norm(dim=-1) - r[:, None] - r[None]
    bound = (v[:, None] - v[None]).norm(dim=-1) * DT + 0.01
    assert not (edges & (gap > bound)).any()
    assert int(edges.sum()) < int((gap <= bound).sum() - n)  # it does leave pairs out


def test_spheres_moving_as_one_are_not_linked_unless_within_epsilon():
    pos, _, radius = random_spheres(60, 3, side=5.0, speed=0.0, min_gap=0.011)
    common = torch.tensor([[4.0, -3.0, 6.0]]).expand(60, 3)
    state = make_state(pos, common, radius, dt=DT)
    assert GraphBuilder("approach", epsilon=0.01)(state).pp_index.shape[1] == 0
    assert GraphBuilder("vi", epsilon=0.01)(state).pp_index.shape[1] > 0  # vi: |v_i| + |v_j|
    # a pair within ε stays linked (resting contacts)
    touching = make_state([[0, 0, 3], [0.905, 0, 3]], common[:2], 0.45, dt=DT)
    assert GraphBuilder("approach", epsilon=0.01)(touching).pp_index.shape[1] == 2


@pytest.mark.parametrize("seed", [0, 1])
def test_approach_links_a_bounded_plane_that_the_ballistic_motion_reaches(seed):
    """A tilted static rectangle; spheres in front of it, each moving with its ballistic
    velocity v + g dt over the frame: a sphere that touches the rectangle at a sampled τ has
    an edge to it."""
    rect = make_plane((0, 0, 3.0), (0, 0.6, 0.8), (1, 0, 0), 2.0, 1.5)
    rng = np.random.default_rng(seed)
    pos = rng.uniform([-3.5, -3, 1.0], [3.5, 3, 6.0], (400, 3))
    radius = rng.uniform(0.2, 0.5, 400)
    height = (pos - rect[:3]) @ rect[3:6]
    keep = height > 0  # in front of the one-sided plane
    pos, radius = pos[keep], radius[keep]
    vel = rng.normal(0, 5.0, pos.shape)
    n = len(pos)
    state = make_state(pos, vel, radius, planes=[rect], kinds=[STATIC], dt=DT)
    graph = GraphBuilder("approach", epsilon=0.01)(state)
    has_edge = torch.zeros(n, dtype=torch.bool)
    has_edge[graph.ps_index[1, graph.ps_index[0] == 1]] = True
    ballistic = torch.as_tensor(vel, dtype=torch.float64) - torch.tensor([0, 0, G * DT])
    tau = torch.linspace(0, DT, 401, dtype=torch.float64)
    centres = torch.as_tensor(pos)[None] + tau[:, None, None] * ballistic[None]  # [T, N, 3]
    plane = torch.as_tensor(rect, dtype=torch.float64)
    dist = rectangle_offset(centres, plane).norm(dim=-1)  # [T, N]
    touch = (dist <= torch.as_tensor(radius)[None]).any(0)
    assert int(touch.sum()) >= 10
    assert not (touch & ~has_edge).any(), (touch & ~has_edge).nonzero().flatten().tolist()
    assert int(has_edge.sum()) < n  # far spheres have none


# ----- relative pair inputs, mass ratios ---------------------------------------------------------
def crowd(seed: int = 0, n: int = 12):
    """``n`` spheres close together on and above the ground, moving towards one another
    (many pp edges), with materials; the state at the last of 4 frames (no gravity history)."""
    rng = np.random.default_rng(seed)
    pos = np.stack([rng.uniform(0, 2.5, n), rng.uniform(0, 2.5, n), rng.uniform(0.5, 2.0, n)], 1)
    vel = rng.normal(0, 1.0, (n, 3)) - 0.5 * (pos - pos.mean(0))
    mass = rng.uniform(0.5, 3.0, n)
    return scene(pos, vel, [0.5] * n, mass=mass, material=rng.integers(0, 2, n))


def test_a_common_velocity_changes_no_pp_input():
    sim = make()
    state = crowd()
    moved = state.clone()
    moved.vel = state.vel + torch.tensor([7.0, -5.0, 3.0])  # every frame of the history
    graph, graph_moved = sim.graph_builder(state), sim.graph_builder(moved)
    assert graph.pp_index.shape[1] >= 10
    assert torch.equal(graph.pp_index, graph_moved.pp_index)
    pp, _ = sim.edge_features(graph, state)
    pp_moved, _ = sim.edge_features(graph_moved, moved)
    assert pp.shape[1] == 4 + 17
    assert_close(pp_moved, pp, rtol=1e-5, atol=1e-5)
    # control: the node inputs (absolute velocities) do see the common velocity
    assert not torch.allclose(sim.node_features(moved), sim.node_features(state))


def test_every_mass_times_1000_leaves_the_prediction_unchanged():
    sim = make()
    state = crowd(seed=1)
    heavy = state.clone()
    heavy.mass = state.mass * 1000.0
    with torch.no_grad():
        pred, graph = sim.normalized_prediction(state)
        pred_heavy, _ = sim.normalized_prediction(heavy)
        assert bool(sim.in_reach(state, graph).any())  # the network decides somewhere
        assert_close(pred_heavy, pred)
        for a, b in zip(sim(heavy), sim(state), strict=True):
            assert_close(a, b)
        # control: the report's model reads the absolute mass
        report = make(**REPORT_MODEL)
        assert not torch.allclose(report(heavy)[0], report(state)[0])


# ----- mean aggregation ---------------------------------------------------------------------------
def star(k: int):
    """Node 0 with ``k`` identical neighbours (paired layout: leaf → centre, then reverse):
    node inputs ``[k + 1, 5]``, pp index ``[2, 2k]``, pp inputs ``[2k, 4]``, no ps edge."""
    x = torch.cat(
        [
            torch.tensor([[0.3, -0.2, 0.5, 0.1, 0.0]]),
            torch.tensor([[-0.4, 0.7, 0.2, 0.9, 1.0]]).expand(k, 5),
        ]
    )
    leaves = torch.arange(1, k + 1)
    centre = torch.zeros(k, dtype=torch.long)
    index = torch.cat([torch.stack([leaves, centre]), torch.stack([centre, leaves])], 1)
    attr = torch.tensor([[0.6, -0.3, 0.2, 0.7]]).expand(k, 4)
    attr = torch.cat([attr, attr * torch.tensor([-1.0, -1, -1, 1])])
    return x, index, attr, torch.zeros(2, 0, dtype=torch.long), torch.zeros(0, 10)


def test_inverse_degree_counts_the_incoming_edges():
    index = torch.tensor([0, 0, 0, 2, 0, 2])
    inv = inverse_degree(index, 4, torch.zeros(1, dtype=torch.float64))
    assert inv.dtype == torch.float64 and inv.shape == (4, 1)
    assert_close(inv[:, 0], torch.tensor([1 / 4, 1.0, 1 / 2, 1.0], dtype=torch.float64))


@pytest.mark.parametrize("k", [6, 12])
def test_a_star_of_k_identical_neighbours_sums_k_times_and_averages_to_one(k):
    torch.manual_seed(0)
    net = EncodeProcessDecode(Widths(5, 4, 10), hidden=16, M=2, aggregation="mean")
    net.eval()
    with torch.no_grad():
        aggs, outs = {}, {}
        for size in (1, k):
            x, index, attr, ps_index, ps_attr = star(size)
            v, e = net.node_encoder(x), net.pp_encoder(attr)
            aggs[size], _ = net.blocks[0].pp(v, index, e)  # the summed messages
            inv = inverse_degree(index[1], size + 1, v)
            assert_close(inv[0, 0], torch.tensor(1.0 / size))
            aggs[size] = (aggs[size], aggs[size] * inv)
            outs[size] = net(x, index, attr, ps_index, ps_attr)
        (sum_1, mean_1), (sum_k, mean_k) = aggs[1], aggs[k]
        assert float(sum_1[0].abs().max()) > 0
        assert_close(sum_k[0], k * sum_1[0])  # the sum grows k-fold
        assert_close(mean_k[0], mean_1[0])  # the mean does not
        assert_close(outs[k][0], outs[1][0])  # nor the centre's prediction
        assert_close(outs[k][1:], outs[1][1:].expand(k, -1))  # every leaf as the one
        summed = EncodeProcessDecode(Widths(5, 4, 10), hidden=16, M=2, aggregation="sum")
        summed.load_state_dict(net.state_dict())
        assert not torch.allclose(summed(*star(k))[0], summed(*star(1))[0])  # control


def test_index_sum_of_identical_messages_is_k_times_one():
    message = torch.tensor([[0.5, -1.5, 2.0]])
    for k in (1, 6, 12):
        index = torch.zeros(k, dtype=torch.long)
        total = IndexSum()(message.expand(k, 3), index, dim_size=1)
        assert_close(total, k * message)
        assert_close(total * inverse_degree(index, 1, total), message)


# ----- a block in free flight ---------------------------------------------------------------------
def flying_block(frames: int = 3) -> Trajectory:
    """27 spheres on a 3 × 3 × 3 lattice 50 m up (radii 0.4–0.6, gaps ≥ 0.05 m > ε), all with
    one velocity and the exact ballistic history of it; only the ground. Every coordinate
    stays within [32, 64), one binade of float32: a common float32 displacement then moves
    every sphere by exactly the same amount, and the differences of centres are exact."""
    rng = np.random.default_rng(5)
    grid = np.array(list(itertools.product(range(3), repeat=3)), dtype=np.float32) * 1.25
    n = len(grid)
    p0 = grid + np.array([40.0, 40.0, 50.0], np.float32)
    v0 = np.array([1.5, -0.7, 2.0])
    t = np.arange(frames)[:, None, None] * 0.1
    g = np.array([0.0, 0.0, -G])
    shift = (v0 * t + 0.5 * g * t**2).astype(np.float32)  # [frames, 1, 3]
    return Trajectory(
        name="block",
        pos=p0[None] + shift,  # float32 sums
        quat=np.tile(np.array([1.0, 0, 0, 0], np.float32), (frames, n, 1)),
        vel=np.broadcast_to(v0 + g * t, (frames, n, 3)).astype(np.float32),
        angvel=np.broadcast_to([0.3, -0.2, 0.1], (frames, n, 3)).astype(np.float32),
        radius=rng.uniform(0.4, 0.6, n).astype(np.float32),
        mass=rng.uniform(0.5, 3.0, n).astype(np.float32),
        material=rng.integers(0, 2, n),
        planes=ground_plane()[None],
        plane_kind=np.array([0]),
        materials=MATERIALS,
        dt=0.1,
        effects=Effects(),
    )


def test_a_block_in_free_flight_has_no_pp_edge_and_flies_ballistically():
    from torch_geometric.data import Batch

    from physgnn.data.state import TrajectoryFrames

    sim = make()
    state = Batch.from_data_list([TrajectoryFrames(flying_block()).state(2, 2)])
    assert state.pos.shape[0] >= 24
    with torch.no_grad():
        vel, angvel, graph = sim.predict(state)
    assert graph.pp_index.shape[1] == 0
    assert not sim.in_reach(state, graph).any()
    expected = state.vel[:, 0].clone()
    expected[:, 2] = expected[:, 2] - G * state.scene_dt
    assert torch.equal(vel, expected) and torch.equal(angvel, state.angvel[:, 0])


def test_a_rollout_keeps_every_distance_of_a_flying_block():
    sim = make()
    sim.effects_trained.fill_(True)
    truth = flying_block(frames=10)
    (pred,) = rollout(sim, [truth])
    assert pred.diverged_at is None and pred.n_frames == 10
    pos = torch.as_tensor(pred.pos)
    assert pos.dtype == torch.float32 and pos.shape == (10, 27, 3)
    rel = pos[:, :, None] - pos[:, None, :]  # [T, N, N, 3] every pair's offset
    assert torch.equal(rel, rel[:1].expand_as(rel))  # exactly: a rigid translation
    assert float(pos[-1, :, 2].min()) > 40  # still far from the ground
    assert float((pos[-1] - pos[2]).abs().max()) > 1.0  # it did fly


# ----- the rest decision --------------------------------------------------------------------------
def resting_pair_and_a_faller():
    state = scene([[0, 0, 0.5], [1.0, 0, 0.5], [5, 0, 3]], [[0, 0, 0]] * 3, [0.5] * 3)
    state.vel[2, 1:] = torch.tensor([0.0, 0.0, G * 0.1])  # ballistic history: out of reach
    state.angvel[:] = torch.tensor([0.2, 0.1, -0.3])
    return state


def test_a_positive_rest_logit_in_reach_stops_the_sphere_a_negative_one_does_not():
    sim = make()
    state = resting_pair_and_a_faller()
    reach = torch.tensor([True, True, False])
    rest = sim.outputs.slice("rest").start  # the last column
    pred = torch.randn(3, rest + 1, generator=torch.Generator().manual_seed(0))
    pred[:, rest] = torch.tensor([2.0, -2.0, 2.0])
    vel, angvel = sim.to_physical(state, pred, reach)
    never = torch.cat([pred[:, :rest], torch.full((3, 1), -10.0)], 1)  # no sphere at rest
    network_vel, network_angvel = sim.to_physical(state, never, reach)
    assert torch.equal(vel[0], torch.zeros(3)) and torch.equal(angvel[0], torch.zeros(3))
    assert torch.equal(vel[1], network_vel[1]) and torch.equal(angvel[1], network_angvel[1])
    dvel = pred[1, :3] * sim.delta_vel_std + sim.delta_vel_mean
    assert_close(vel[1], state.vel[1, 0] + dvel)
    # out of reach: free flight, whatever the logit
    assert_close(vel[2], state.vel[2, 0] - torch.tensor([0.0, 0.0, G * 0.1]))
    assert torch.equal(angvel[2], state.angvel[2, 0])


def test_the_decoders_rest_logit_decides_end_to_end():
    sim = make()
    state = resting_pair_and_a_faller()
    decoder = sim.network.decoder.lin2
    rest = sim.outputs.slice("rest").start
    with torch.no_grad():
        decoder.weight[rest].zero_()
        decoder.bias[rest] = 50.0  # "at rest" for every sphere
        vel, angvel, graph = sim.predict(state)
        assert sim.in_reach(state, graph).tolist() == [True, True, False]
        assert torch.equal(vel[:2], torch.zeros(2, 3)) and torch.equal(
            angvel[:2], torch.zeros(2, 3)
        )
        assert_close(vel[2], torch.tensor([0.0, 0.0, -G * 0.1]))
        decoder.bias[rest] = -50.0
        vel, angvel, _ = sim.predict(state)
        plain = make(rest_decision=False)
        plain.load_state_dict(
            {
                k: v[:rest] if k.startswith("network.decoder.lin2") else v
                for k, v in sim.state_dict().items()
            }
        )
        vel_plain, angvel_plain = plain(state)[:2]
        assert_close(vel, vel_plain) and assert_close(angvel, angvel_plain)
        assert float(vel[:2].abs().max()) > 0


def test_rest_target_labels():
    sim = make()
    state = scene([[3.0 * k, 0, 0.5] for k in range(6)], [[0, 0, 0]] * 6, [0.5] * 6)
    state.target_vel = torch.tensor(
        [[0, 0, 0], [0.005, 0, 0], [0.02, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0.0099, 0]]
    )
    # |ω|·r: 0, 0, 0, 0.015, 0.005, 0.005 (r = 0.5)
    state.target_angvel = torch.tensor(
        [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.03, 0, 0], [0, 0.01, 0], [0, 0, 0.01]]
    )
    assert sim.contacts.rest_speed == 0.01
    assert sim.rest_target(state).tolist() == [True, True, False, False, True, True]


# ----- dense-contact layouts ----------------------------------------------------------------------
def gaps_to_earlier(pos, radius):
    """``[N, N]`` surface gaps (pairs i > j only, others +inf)."""
    gap = np.linalg.norm(pos[:, None] - pos[None], axis=-1) - radius[:, None] - radius[None]
    return np.where(np.tril(np.ones_like(gap, dtype=bool), -1), gap, np.inf)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_aggregate_touches_without_overlap_and_stands_on_z0(seed):
    rng = np.random.default_rng(seed)
    radius = rng.uniform(0.5, 1.0, 20)
    pos = aggregate_positions(rng, radius, max_gap=0.1)
    gap = gaps_to_earlier(pos, radius)
    assert gap[np.isfinite(gap)].min() > -OVERLAP_TOL - 1e-12  # no overlap
    nearest = gap[1:].min(axis=1)  # every sphere after the first near an earlier one
    assert np.all(nearest <= 0.1 + 1e-9) and np.all(nearest > -OVERLAP_TOL - 1e-12)
    assert np.isclose(nearest, 0.0, atol=1e-9).sum() >= 3  # about half touch exactly
    assert (pos[:, 2] - radius).min() == pytest.approx(0.0, abs=1e-12)
    assert float(np.ptp(pos[:, 2])) > 0.5  # three-dimensional, no plain layer


@pytest.mark.parametrize("seed", [0, 1])
def test_a_row_lies_on_the_ground_along_one_horizontal_line(seed):
    rng = np.random.default_rng(seed)
    radius = rng.uniform(0.5, 1.0, 10)
    pos = row_positions(rng, radius, max_gap=0.1)
    gap = gaps_to_earlier(pos, radius)
    assert gap[np.isfinite(gap)].min() > -1e-9  # no overlap
    assert_close(torch.as_tensor(pos[:, 2]), torch.as_tensor(radius))  # on the ground
    assert_close(torch.as_tensor(pos[:, :2].mean(0)), torch.zeros(2, dtype=torch.float64))
    flat = pos[:, :2] - pos[0, :2]
    direction = flat[-1] / np.linalg.norm(flat[-1])
    across = flat - (flat @ direction)[:, None] * direction
    assert np.abs(across).max() < 1e-9  # one straight horizontal line, in order
    assert np.all(np.diff(flat @ direction) > 0)


def test_row_neighbours_are_spaced_as_documented():
    rng = np.random.default_rng(0)
    radius = rng.uniform(0.5, 1.0, 10)
    pos = row_positions(rng, radius, max_gap=0.1)
    assert_close(torch.as_tensor(pos[:, 2]), torch.as_tensor(radius))  # on the ground
    horizontal = np.linalg.norm(np.diff(pos[:, :2], axis=0), axis=1) - radius[1:] - radius[:-1]
    assert np.all(horizontal >= -1e-9) and np.all(horizontal <= 0.1 + 1e-9)
    assert np.isclose(horizontal, 0.0, atol=1e-9).sum() >= 2  # about half with no gap
    gap = np.linalg.norm(np.diff(pos, axis=0), axis=1) - radius[1:] - radius[:-1]
    assert np.all(gap >= horizontal - 1e-9)  # never closer than the horizontal spacing


def test_dense_contact_scenes_validate_and_flying_aggregates_move_as_one():
    cfg = scene_cfg("random_box", dense_max_gap=0.1)
    kinds = {"flying": 0, "settling": 0, "row": 0}
    for seed in range(30):
        s = dense_contact(cfg, np.random.default_rng(seed))  # validated by _finish
        n = len(s.pos)
        assert n >= 1 and np.all(np.abs(s.pos[:, :2]) + s.radius[:, None] <= 15.0)
        i, j = np.triu_indices(n, 1)
        gap = np.linalg.norm(s.pos[i] - s.pos[j], axis=1) - s.radius[i] - s.radius[j]
        assert n == 1 or gap.min() > -1e-4  # float32 centres
        assert np.all(s.angvel == 0)
        if np.all(s.vel == 0):
            kinds["settling"] += 1
            assert (s.pos[:, 2] - s.radius).min() == pytest.approx(0.0, abs=1e-5)
        elif np.all(s.vel[:, 2] == 0) and np.allclose(s.pos[:, 2], s.radius):
            kinds["row"] += 1
            assert np.all(s.vel == s.vel[0]) and np.linalg.norm(s.vel[0]) >= 0.5 - 1e-6
        else:
            kinds["flying"] += 1
            assert np.all(s.vel == s.vel[0])  # one common velocity
            assert (s.pos[:, 2] - s.radius).min() >= 1.0 - 1e-5  # in the air
    assert min(kinds.values()) >= 3, kinds
