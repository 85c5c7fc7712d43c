"""The planes by Newton's law (model.contacts.plane_newton): with any weights, the move never
crosses a plane, and a sphere dropped in free flight rebounds with its contact's restitution."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
import torch
from simdata import STATS

from physgnn.data.state import TrajectoryFrames
from physgnn.graph.builder import GraphBuilder
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.oracles import sphere_scene
from physgnn.models.learned import LearnedSimulator
from physgnn.models.options import ContactHandling, ModelInputs
from physgnn.nn.epd import EncodeProcessDecode
from physgnn.rollout import rollout

ENGINE = STATS | {"substeps": 10}
G = 9.81


def sinking_model(newton: bool, seed: int = 0) -> LearnedSimulator:
    """The default model on the engine state (H = 1, 1 block of 8 units), random weights, its
    node decoder's own change of the move 15 m/s down for every sphere at a plane."""
    torch.manual_seed(seed)
    network = partial(EncodeProcessDecode, M=1, hidden=8)
    sim = LearnedSimulator(
        ENGINE,
        H=1,
        network=network,
        inputs=ModelInputs(engine_state=True),
        # the control has neither last floor: the energy guard's floors the move too
        contacts=ContactHandling(plane_newton=newton, energy_guard=newton),
    )
    last = [m for m in sim.network.decoder.modules() if isinstance(m, torch.nn.Linear)][-1]
    down = sim.outputs.slice("delta_mean_vel").start + 2
    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()
        last.bias[down] = -15.0 / float(sim.delta_vel_std[2])
    sim.effects_trained.fill_(True)  # as if trained on every effect: no warning
    return sim.eval()


@pytest.fixture(scope="module")
def landing():
    """Six spheres (r 0.5 m) thrown down and sideways onto the ground from 1–4 m, 12 frames."""
    rng = np.random.default_rng(3)
    pos = np.c_[rng.uniform(-6, 6, (6, 2)), rng.uniform(1.0, 4.0, 6)]
    vel = np.c_[rng.uniform(-3, 3, (6, 2)), rng.uniform(-8, 0, 6)]
    scene = sphere_scene(pos, vel=vel, material=(0.7, 0.5, 0.0, 0.0), n_frames=12)
    return simulate(scene, {"substeps": 10})


def lowest_clearance(pred) -> float:
    return float((pred.pos[..., 2] - pred.radius).min())


def test_with_any_weights_no_move_crosses_the_ground(landing):
    with torch.no_grad():
        crossed = rollout(sinking_model(newton=False), [landing])[0]
        kept = rollout(sinking_model(newton=True), [landing])[0]
    assert lowest_clearance(crossed) < -0.05  # the network's own change sinks spheres
    assert lowest_clearance(kept) >= -1e-4  # the move may not cross the plane


def test_the_decoders_own_change_starts_at_zero_and_acts_only_where_a_plane_stops_the_move():
    sim = sinking_model(newton=True)
    fresh = LearnedSimulator(
        ENGINE,
        H=1,
        network=partial(EncodeProcessDecode, M=1, hidden=8),
        inputs=ModelInputs(engine_state=True),
        contacts=ContactHandling(plane_newton=True),
    )
    last = [m for m in fresh.network.decoder.modules() if isinstance(m, torch.nn.Linear)][-1]
    for name in ("delta_vel", "delta_angvel", "delta_mean_vel", "delta_mean_angvel"):
        assert not last.weight[fresh.outputs.slice(name)].any()
        assert not last.bias[fresh.outputs.slice(name)].any()
    # one sphere leaving the ground at 3 m/s (0.35 m up at frame 1), one resting on it: the
    # decoder asks both for 15 m/s down; only the resting one, which the ground stops, gets it
    # (then floored)
    truth = simulate(
        sphere_scene([[0.0, 0, 0.6], [4.0, 0, 0.5]], vel=[[0, 0, 3.0], [0, 0, 0]]), {"substeps": 10}
    )
    state = TrajectoryFrames(truth, engine_state=True).state(1, 1)
    graph = GraphBuilder()(state, (state.vel[:, 0],))
    with torch.no_grad():
        out = sim.network_prediction(state, graph, on_plane=torch.ones(2, dtype=torch.bool))
    columns = sim.outputs.slice("delta_mean_vel")
    change = out[:, columns] * sim.delta_vel_std + sim.delta_vel_mean  # ū − v_t, m/s
    fall = -G * float(state.dt[0]) * float(sim.gravity_share)
    assert abs(float(change[0, 2]) - fall) < 1e-3  # its flight, ballistic
    assert abs(float(change[1, 2])) < 1e-3  # resting: stopped by the ground, not sunk
