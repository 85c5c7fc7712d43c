"""LearnedSimulator: normalisation, target round trip, rotation switch, invariances, buffers."""

from __future__ import annotations

import pytest
import torch
from simdata import STATS, batch, trajectory
from torch.testing import assert_close

from physgnn.models.learned import LearnedSimulator, StatsError
from physgnn.models.profiling import StepTimer
from physgnn.physics.scene import Effects


def make(**kwargs) -> LearnedSimulator:
    torch.manual_seed(0)
    args = dict(H=2, M=2, hidden=16) | kwargs
    return LearnedSimulator(STATS, **args)


def test_forward_shapes_and_timings():
    sim, timer = make(), StepTimer()  # timing is opt-in, outside the simulator
    state = batch([trajectory(3, seed=0), trajectory(5, seed=1)])
    with timer.watch(sim):
        vel, angvel = timer.predict(sim, state)
    assert vel.shape == (8, 3) and angvel.shape == (8, 3)
    assert torch.isfinite(vel).all() and torch.isfinite(angvel).all()
    assert timer.timings["graph"] > 0 and timer.timings["network"] > 0
    timer.reset()
    assert {k: timer.timings[k] for k in ("graph", "network")} == {"graph": 0.0, "network": 0.0}
    assert sim.graph_builder.__class__.__name__ == "GraphBuilder"  # unwrapped again


def test_node_features_by_hand():
    sim = make(H=1)
    state = batch([trajectory(2, seed=3)], t=4, H=3)  # a longer history than the model's
    x = sim.node_features(state)
    assert x.shape == (2, 6 * 2 + 2)
    mean, std = torch.tensor(STATS["vel"]["mean"]), torch.tensor(STATS["vel"]["std"])
    assert_close(x[0, 0:3], (state.vel[0, 0] - mean) / std)
    assert_close(x[0, 3:6], (state.vel[0, 1] - mean) / std)
    assert_close(x[1, 6:9], state.angvel[1, 0] / 0.5)
    assert_close(x[1, 12], (state.radius[1] - 0.5) / 0.1)
    assert_close(x[1, 13], (state.mass[1] - 2.0) / 0.5)


def test_edge_features_scaled_by_length_and_velocity_std():
    sim = make(length_scale=2.0)
    state = batch([trajectory(3, seed=0)])
    graph = sim.graph_builder(state)
    pp, ps = sim.edge_features(graph)
    assert_close(pp, graph.pp_attr / 2.0)
    assert_close(ps[:, :3], graph.ps_attr[:, :3] / torch.tensor([1.0, 2.0, 4.0]))
    assert_close(ps[:, 3:6], graph.ps_attr[:, 3:6])
    assert_close(ps[:, 6:], graph.ps_attr[:, 6:] / 2.0)


def test_default_length_scale_is_mean_diameter():
    assert float(make().length_scale) == pytest.approx(1.0)


def test_target_round_trip_gives_ground_truth():
    sim = make()
    state = batch([trajectory(4, seed=2)])
    vel, angvel = sim.to_physical(state, sim.normalized_target(state))
    assert_close(vel, state.target_vel)
    assert_close(angvel, state.target_angvel)


def test_zero_output_means_mean_change():
    sim = make()
    state = batch([trajectory(3, seed=2)])
    vel, angvel = sim.to_physical(state, torch.zeros(3, 6))
    assert_close(vel, state.vel[:, 0] + torch.tensor([0.0, 0.0, -0.9]))
    assert_close(angvel, state.angvel[:, 0])


def test_rotation_off_keeps_angular_velocity():
    sim = make()
    still = trajectory(3, seed=4, effects=Effects(rotation=False))
    state = batch([trajectory(2, seed=5), still])
    _, angvel = sim(state)
    assert torch.equal(angvel[2:], state.angvel[2:, 0])
    assert not torch.equal(angvel[:2], state.angvel[:2, 0])


@pytest.mark.parametrize("gns_style", [False, True])
def test_horizontal_translation_invariance(gns_style):
    """Also for the GNS-style model, whose boundary distances move with the planes."""
    sim = make(boundary_features=True, use_surfaces=False) if gns_style else make()
    state = batch([trajectory(4, seed=6)])
    moved = state.clone()
    shift = torch.tensor([3.5, -2.0, 0.0])
    moved.pos = state.pos + shift
    moved.planes = state.planes.clone()
    moved.planes[:, :3] += shift
    for a, b in zip(sim(state), sim(moved), strict=True):
        assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_checkpoint_is_self_contained():
    sim = make(length_scale=0.7)
    sim.effects_trained.fill_(True)
    sd = sim.state_dict()
    assert "effects_trained" in sd and "delta_vel_std" in sd
    stats = LearnedSimulator.stats_from_state_dict(sd)
    assert stats["delta_vel"]["std"] == pytest.approx(STATS["delta_vel"]["std"])
    assert stats["mass"]["mean"] == pytest.approx(2.0)
    twin = LearnedSimulator(stats, H=2, M=2, hidden=16)
    twin.load_state_dict(sd)
    state = batch([trajectory(3, seed=7)])
    assert_close(twin(state)[0], sim(state)[0])
    assert bool(twin.effects_trained.all())


def test_missing_stats_is_one_clear_line():
    bad = {k: v for k, v in STATS.items() if k != "delta_angvel"}
    with pytest.raises(StatsError, match=r"lack 'delta_angvel.mean'"):
        LearnedSimulator(bad)
    bad = dict(STATS, vel={"mean": [0.0, 0.0], "std": [1.0, 1.0, 1.0]})
    with pytest.raises(StatsError, match=r"'vel.mean' has shape \(2,\)"):
        LearnedSimulator(bad)


def test_history_mismatch_raises():
    sim = make(H=3)
    with pytest.raises(ValueError, match="needs 4"):
        sim(batch([trajectory(2, seed=0)], t=3, H=1))


def test_material_embedding_changes_the_prediction():
    sim = make(num_materials=3, material_dim=4)
    state = batch([trajectory(3, seed=9)])
    before = sim(state)[0]
    state.material = torch.tensor([2, 1, 0])
    assert not torch.equal(sim(state)[0], before)
    state.material = torch.tensor([0, 0, 3])
    with pytest.raises(ValueError, match="material id 3 out of range"):
        sim(state)
