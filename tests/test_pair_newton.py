"""Sphere pairs by Newton's law (physgnn/models/pair_newton.py): a pair that meets within the frame
in free flight leaves with its restitution in closed form, momentum exact; hand-built pairs and
a simulator whose network adds nothing."""

from types import SimpleNamespace

import torch
from simdata import STATS, head_on, learned
from torch_geometric.data import Batch

from physgnn.data.state import TrajectoryFrames
from physgnn.models.pair_newton import pair_bounces

DT = 0.1
F64 = torch.float64


def spheres(pos, vel, radius, mass, restitution):
    """Hand-built spheres (float64) with the fields :func:`pair_bounces` reads."""
    n = len(pos)
    params = torch.zeros(n, 4, dtype=F64)
    params[:, 0] = torch.tensor(restitution, dtype=F64)
    return SimpleNamespace(
        pos=torch.tensor(pos, dtype=F64),
        vel=torch.tensor(vel, dtype=F64),
        radius=torch.tensor(radius, dtype=F64),
        mass=torch.tensor(mass, dtype=F64),
        scene_dt=torch.full((n,), DT, dtype=F64),
        material_params=params,
    )


def paired(pairs):
    """``[2, 2P]``: each pair (src, dst) then its reverse, the paired layout."""
    src, dst = torch.tensor(pairs).T
    return torch.stack([torch.cat([src, dst]), torch.cat([dst, src])])


FREE = torch.ones(2, dtype=torch.bool)


def test_a_head_on_pair_meets_mid_frame_and_leaves_by_newtons_law():
    # gap 0.1 m closed at 8 m/s: they meet at τ = 0.0125 s; e = 0.8 · 1.0; masses 1 : 8
    state = spheres([[0, 0, 0], [1.6, 0, 0]], [[4, 0, 0], [-4, 0, 0]], [0.5, 1], [1, 8], [0.8, 1])
    end, mean = pair_bounces(state, paired([[0, 1]]), FREE)
    change = 1.8 * 8.0  # (1 + e)·w
    expected = torch.tensor([[-change * 8 / 9, 0, 0], [change / 9, 0, 0]], dtype=F64)
    torch.testing.assert_close(end, expected)
    torch.testing.assert_close(mean, expected * (DT - 0.0125) / DT)
    mass = state.mass[:, None]
    torch.testing.assert_close((mass * end).sum(0), torch.zeros(3, dtype=F64))
    torch.testing.assert_close((mass * mean).sum(0), torch.zeros(3, dtype=F64))
    after = state.vel + end  # the relative speed reverses, times e
    torch.testing.assert_close(after[0, 0] - after[1, 0], torch.tensor(-0.8 * 8.0, dtype=F64))


def test_an_oblique_meeting_keeps_the_tangential_motion_and_adds_no_energy():
    state = spheres(
        [[0, 0, 0], [1.2, 0.7, 0.1]], [[3, 1, 0], [-2, 0, 0.5]], [0.5, 0.6], [2, 3], [0.9, 0.7]
    )
    end, _ = pair_bounces(state, paired([[0, 1]]), FREE)
    assert end.abs().sum() > 0
    after = state.vel + end
    # the change lies along one line, the normal: the relative velocity across it is kept
    normal = end[0] / end[0].norm()
    before_rel, after_rel = state.vel[0] - state.vel[1], after[0] - after[1]
    torch.testing.assert_close(
        before_rel - (before_rel @ normal) * normal, after_rel - (after_rel @ normal) * normal
    )
    torch.testing.assert_close(after_rel @ normal, -0.63 * (before_rel @ normal))

    def energy(v):
        return 0.5 * (state.mass[:, None] * v.square()).sum()

    assert energy(after) <= energy(state.vel)


def test_pairs_that_do_not_meet_in_the_frame_or_touch_a_plane_are_left_to_the_network():
    cases = [
        ([[0, 0, 0], [3.0, 0, 0]], [[4, 0, 0], [-4, 0, 0]]),  # gap 2 m: meets after the frame
        ([[0, 0, 0], [1.1, 0, 0]], [[-1, 0, 0], [1, 0, 0]]),  # parting
        ([[0, 0, 0], [1.1, 2.0, 0]], [[4, 0, 0], [-4, 0, 0]]),  # passes by
        ([[0, 0, 0], [1.1, 0, 0]], [[0, 0, -3], [0, 0, -3]]),  # falling together
    ]
    for pos, vel in cases:
        state = spheres(pos, vel, [0.5, 0.5], [1, 1], [1, 1])
        for part in pair_bounces(state, paired([[0, 1]]), FREE):
            torch.testing.assert_close(part, torch.zeros(2, 3, dtype=F64))
    state = spheres([[0, 0, 0], [1.1, 0, 0]], [[4, 0, 0], [-4, 0, 0]], [0.5, 0.5], [1, 1], [1, 1])
    near_a_plane = torch.tensor([True, False])
    for part in pair_bounces(state, paired([[0, 1]]), near_a_plane):
        torch.testing.assert_close(part, torch.zeros(2, 3, dtype=F64))
    masked = torch.zeros(1, dtype=F64)
    for part in pair_bounces(state, paired([[0, 1]]), FREE, masked):
        torch.testing.assert_close(part, torch.zeros(2, 3, dtype=F64))


def test_a_simulator_whose_network_adds_nothing_answers_a_collision_by_the_law():
    torch.manual_seed(0)
    traj = head_on()
    state = Batch.from_data_list([TrajectoryFrames(traj, engine_state=True).state(0, 0)])
    sim = learned(STATS, H=0, M=1, hidden=8, contact_passes=0, pair_newton=True).eval()
    with torch.no_grad():  # the network's pair impulses: zero
        sim.network.pair_decoder.mlp.lin2.weight.zero_()
    vel, _, mean, _ = sim(state)
    e = 0.5 * 0.5  # both spheres of Material(): restitution 0.5 each
    m0, m1 = (float(m) for m in state.mass)
    change = (1 + e) * 8.0
    gravity = torch.tensor([0, 0, -9.81 * DT])
    expected = state.vel[:, 0] + gravity
    expected[0, 0] -= change * m1 / (m0 + m1)
    expected[1, 0] += change * m0 / (m0 + m1)
    torch.testing.assert_close(vel, expected, atol=1e-5, rtol=1e-5)
    tau = 0.1 / 8.0
    moved = state.vel[:, 0, 0] + (expected[:, 0] - state.vel[:, 0, 0]) * (DT - tau) / DT
    torch.testing.assert_close(mean[:, 0], moved, atol=1e-5, rtol=1e-5)
    momentum = (state.mass[:, None] * (vel - state.vel[:, 0] - gravity)).sum(0)
    torch.testing.assert_close(momentum, torch.zeros(3), atol=1e-4, rtol=0)
