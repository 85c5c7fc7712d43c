"""Contacts stated to the network and taught to it: contact and material features, the
gravity prior, the contact penalty and the contact noise (hand-built scenes, exact values)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from handmade import DT, ballistic, make, scene
from simdata import REPORT_MODEL, learned
from torch.testing import assert_close

from physgnn.graph.rules import ballistic_velocity
from physgnn.models.learned import LearnedSimulator
from physgnn.nn.mlp import MLP
from physgnn.physics.geometry import edge_plane_depth, plane_depth
from physgnn.physics.scene import ground_plane, make_plane
from physgnn.training.contacts import contact_penalty, perturb_contacts


@pytest.mark.parametrize("relative_pairs", [False, True])
def test_pp_contact_features_state_the_gap_and_the_closing_speed(relative_pairs):
    sim = make(length_scale=2.0, relative_pairs=relative_pairs)
    # two spheres 1.7 m apart along x (radii 0.5 and 1: gap 0.2 m), closing at 3 m/s
    state = scene([[0, 0, 5], [1.7, 0, 5]], [[1, 0, 0], [-2, 0, 0]], [0.5, 1.0])
    graph = sim.graph_builder(state)
    pp, _ = sim.edge_features(graph, state)
    assert pp.shape == (2, 4 + 17 if relative_pairs else 6)
    sigma = float(torch.tensor([1.0, 2.0, 4.0]).square().mean().sqrt())
    expected = torch.tensor([0.2 / 2.0, -3.0 / sigma])
    assert_close(pp[0, 4:6], expected)
    assert_close(pp[1, 4:6], expected)  # the same for the reverse edge: the third law holds


def test_relative_pair_inputs_by_hand():
    """The default model's pp columns after [p_i − p_j, |p_i − p_j|] (i the target, edge 0 is
    0 → 1): gap, normal and tangential relative speed, the 3 relative velocities, both radii,
    the mass ratio, the pair's restitution and friction products."""
    sim = make(length_scale=2.0)
    assert sim.inputs.relative_pairs and sim.inputs.mass_ratio
    # sphere 1 passes sphere 0 sideways at 4 m/s (y) while closing at 3 m/s (x)
    state = scene(
        [[0, 0, 5], [1.7, 0, 5]],
        [[1, 0, 0], [-2, 4, 0]],
        [0.5, 1.0],
        mass=[1.0, 3.0],
        material=[0, 1],
    )
    graph = sim.graph_builder(state)
    pp, _ = sim.edge_features(graph, state)
    sigma = float(torch.tensor([1.0, 2.0, 4.0]).square().mean().sqrt())
    restitution, friction = 0.7 * 0.3, 0.5 * 0.9
    dv = torch.tensor([-3.0, 4.0, 0.0]) / sigma  # v_1 − v_0
    edge0 = [0.1, -3.0 / sigma, 4.0 / sigma, *dv.tolist() * 3, 0.5, 0.25, 0.75]
    edge1 = [0.1, -3.0 / sigma, 4.0 / sigma, *(-dv).tolist() * 3, 0.25, 0.5, 0.25]
    expected = torch.tensor([edge0 + [restitution, friction], edge1 + [restitution, friction]])
    assert graph.pp_index[:, 0].tolist() == [0, 1]
    assert_close(pp[:, 4:], expected)


def test_ps_contact_features_state_clearance_normal_and_tangential_speed():
    sim = make(length_scale=2.0)
    state = scene([[0, 0, 0.8]], [[3, 4, -2]], [0.5])  # 0.3 m above the ground
    graph = sim.graph_builder(state)
    _, ps = sim.edge_features(graph, state)
    sigma = float(torch.tensor([1.0, 2.0, 4.0]).square().mean().sqrt())
    assert ps.shape == (1, 15)
    assert_close(ps[0, 10:13], torch.tensor([0.3 / 2.0, -2.0 / sigma, 5.0 / sigma]))
    # then the sphere–plane contact's restitution and friction: the sphere's times the plane's
    assert_close(ps[0, 13:], state.material_params[0, :2] * state.plane_materials[0, :2])
    state.plane_materials = torch.tensor([[0.5, 0.8, 0.0, 0.0]])
    _, ps = sim.edge_features(graph, state)
    assert_close(ps[0, 13:], state.material_params[0, :2] * torch.tensor([0.5, 0.8]))


@pytest.mark.parametrize("mass_ratio", [False, True])
def test_material_values_are_node_features(mass_ratio):
    sim = make(mass_ratio=mass_ratio)
    state = scene([[0, 0, 5], [3, 0, 5]], [[0, 0, 0]] * 2, [0.5, 0.5], material=[1, 0])
    x = sim.node_features(state)
    first = 6 * 3 + 1 + int(not mass_ratio)  # after the velocities, radius (and mass)
    assert x.shape == (2, first + 4)
    assert_close(x[0, first:], torch.tensor([0.3, 0.9, 2.0, 2.0]))
    assert_close(x[1, first:], torch.tensor([0.7, 0.5, 0.5, 0.5]))


def test_report_inputs_are_the_old_widths():
    sim = learned(H=2, M=1, hidden=8, **REPORT_MODEL)
    assert (sim.network.pp_in, sim.network.ps_in, sim.node_in) == (4, 10, 20)


def test_gravity_prior_free_flight_is_exact_whatever_the_mass():
    sim = make(gravity_prior=True)
    for mass in (0.01, 1.0, 1000.0):
        state = scene([[0, 0, 20], [5, 0, 30]], [[1, 2, -3], [0, 0, 4]], [0.5, 0.7], [mass] * 2)
        state = ballistic(state)
        vel, angvel, mean_vel, mean_angvel = sim(state)  # the engine state's four answers
        fall = torch.tensor([0.0, 0.0, -9.81 * DT])
        assert_close(vel, state.vel[:, 0] + fall)
        assert_close(mean_vel, state.vel[:, 0] + 0.5 * fall)  # no substeps known: the parabola
        assert_close(angvel, state.angvel[:, 0])
        assert_close(mean_angvel, state.angvel[:, 0])


def test_gravity_prior_leaves_contacts_to_the_network():
    sim = make(gravity_prior=True)
    # resting on the ground; just out of reach of the ground; within the fall g dt² of it
    reach = 0.01 + 9.81 * DT * DT
    state = scene(
        [[0, 0, 0.5], [5, 0, 0.5 + reach + 1e-3], [-5, 0, 0.5 + reach - 1e-3]],
        [[0, 0, 0]] * 3,
        [0.5] * 3,
    )
    state = ballistic(state)  # at the top of a flight
    pred, graph = sim.normalized_prediction(state)
    assert sim.in_reach(state, graph).tolist() == [True, False, True]
    vel = sim(state)[0]
    network, _ = LearnedSimulator.to_physical(make(gravity_prior=False), state, pred)
    assert_close(vel[[0, 2]], network[[0, 2]])
    assert_close(vel[1], torch.tensor([0.0, 0.0, -9.81 * DT]))


def test_layer_norm_normalises_and_keeps_the_third_law():
    mlp = MLP(3, 8, 5, layer_norm=True)
    out = mlp(torch.randn(7, 3))
    assert_close(out.mean(1), torch.zeros(7), atol=1e-6, rtol=0)
    sim = make(layer_norm=True)
    state = scene([[0, 0, 0.5], [1.0, 0, 0.5]], [[1, 0, 0], [-1, 0, 0]], [0.5, 0.5])
    pred, graph = sim.normalized_prediction(state)
    assert graph.pp_index.shape[1] == 2 and torch.isfinite(pred).all()


def test_edge_plane_depth_matches_the_per_plane_definition():
    gen = torch.Generator().manual_seed(0)
    pos = torch.rand(20, 3, generator=gen, dtype=torch.float64) * 4 - 2
    radius = torch.rand(20, generator=gen, dtype=torch.float64) * 0.5 + 0.2
    ramp = make_plane((0, 0, 0.3), (0, 0.6, 0.8), (1, 0, 0), 1.0, 0.8)
    planes = torch.tensor(np.stack([ground_plane(), ramp]), dtype=torch.float64)
    kinds = torch.tensor([0, 2])
    index = torch.stack([torch.arange(2).repeat_interleave(20), torch.arange(20).repeat(2)])
    depth = edge_plane_depth(pos, radius, planes, kinds, index)
    expected = torch.cat([plane_depth(pos, radius, planes[k], int(kinds[k])) for k in range(2)])
    assert_close(depth, expected)


def test_contact_penalty_is_the_squared_excess_depth_in_velocity_units():
    # predicted next positions: the pair overlaps by 0.3 m, the first sphere 0.1 m in the ground
    state = scene([[0, 0, 0.45], [0.7, 0, 0.5]], [[0, 0, 0]] * 2, [0.5, 0.5])
    graph = make().graph_builder(state)
    vel_next = torch.zeros(2, 3)
    vel_next[0, 2] = -0.05 / DT  # to 0.40: 0.1 m into the ground
    penalty = contact_penalty(state, vel_next, graph, tol=0.02, speed_scale=2.0)
    depth_pp = 1.0 - float(np.hypot(0.7, 0.1))
    excess = torch.tensor([depth_pp - 0.02, 0.1 - 0.02, 0.0])
    assert_close(penalty, (excess / (DT * 2.0)).square().sum() / 2, rtol=1e-5, atol=1e-7)
    apart = contact_penalty(state, torch.tensor([[-5.0, 0, 5], [5.0, 0, 5]]), graph, 0.02, 2.0)
    assert float(apart) == 0.0


def test_contact_noise_pushes_contacts_in_and_targets_the_truth():
    # a touching pair resting on the ground, a third sphere far from everything but the ground
    state = scene([[0, 0, 0.5], [1.0, 0, 0.5], [5, 0, 3]], [[0, 0, 0]] * 3, [0.5] * 3)
    state.target_vel = torch.zeros(3, 3)
    graph = make().graph_builder(state)
    gen = torch.Generator().manual_seed(3)
    out = perturb_contacts(state, graph, depth=0.2, touch=0.01, prob=1.0, generator=gen)
    shift = out.pos - state.pos
    assert_close(shift[2], torch.zeros(3))  # no contact: untouched
    along, down = shift[:, 0], shift[:, 2]
    assert float(along[0]) > 0 and float(along[1]) < 0  # the pair moved towards each other
    assert_close(along[0], -along[1])  # u/2 each
    assert 0 < float(along[0]) <= 0.1 and -0.2 <= float(down[0]) < 0 and float(down[1]) < 0
    assert_close(out.target_vel, -shift / DT)  # back onto the truth in one frame
    assert_close(out.vel, state.vel)  # velocities kept
    none = perturb_contacts(state, graph, depth=0.2, touch=0.01, prob=0.0, generator=gen)
    assert torch.equal(none.pos, state.pos)


SWITCHES = [
    ("contact_features", True),
    ("material_features", True),
    ("gravity_prior", True),
    ("connectivity", "approach"),
    ("relative_pairs", True),
    ("mass_ratio", True),
    ("aggregation", "mean"),
    ("rest_decision", True),
]


@pytest.mark.parametrize(("key", "value"), SWITCHES)
def test_each_switch_alone_builds_and_predicts(key, value):
    """Each switch of the default model alone on the report's model."""
    assert REPORT_MODEL.get(key, False) != value
    sim = learned(H=2, M=1, hidden=8, **(REPORT_MODEL | {key: value}))
    state = scene([[0, 0, 0.5], [1.0, 0, 0.5]], [[0, 0, 0]] * 2, [0.5, 0.5])
    vel, angvel = sim(state)
    assert torch.isfinite(vel).all() and torch.isfinite(angvel).all()


def test_with_the_latch_a_sphere_that_bounced_in_the_last_frame_is_left_to_the_network():
    sim = make(gravity_prior=True, recent_contact=True)
    # 0.6 m above the ground moving up at 2 m/s after moving down at 13 m/s: the frame before
    # held an impact, though the ground is now out of reach
    state = scene([[0, 0, 1.1], [5, 0, 5.0]], [[0, 0, 2.0], [0, 0, 2.0]], [0.5, 0.5])
    state.vel[0, 1:] = torch.tensor([0.0, 0.0, -13.0])
    state.vel[1, 1:] = torch.tensor([0.0, 0.0, 2.0 + 9.81 * DT])  # ballistic: free
    pred, graph = sim.normalized_prediction(state)
    assert sim.in_reach(state, graph).tolist() == [True, False]


def test_without_the_latch_a_sphere_that_bounced_in_the_last_frame_flies_ballistically():
    sim = make(gravity_prior=True)  # the default: no latch
    state = scene([[0, 0, 1.1]], [[0, 0, 2.0]], [0.5])
    state.vel[0, 1:] = torch.tensor([0.0, 0.0, -13.0])  # the frame before held an impact
    vel, angvel = sim(state)[:2]
    assert torch.equal(vel, ballistic_velocity(state))
    assert torch.equal(angvel, state.angvel[:, 0])
