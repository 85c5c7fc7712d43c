"""The output contract (physgnn/models/outputs.py) and the one step that the rollout and the
training loss share."""

from __future__ import annotations

import pytest
import torch
from simdata import REPORT_MODEL, batch, learned, trajectory
from torch.testing import assert_close

from physgnn.models.outputs import NODE, NODE_REST, PAIR, node_outputs, velocity_changes
from physgnn.training.lit import LitSimulator


def adam(params):
    return torch.optim.Adam(params, lr=1e-3)


def test_blocks_tile_the_outputs_by_name():
    assert NODE.names == ("delta_vel", "delta_angvel") and NODE.width == 6
    assert NODE_REST.slice("rest") == slice(6, 7) and NODE_REST.width == 7
    assert PAIR.slice("impulse") == slice(0, 3) and PAIR.slice("couple") == slice(3, 6)
    assert node_outputs(True) is NODE_REST and node_outputs(False) is NODE
    out = torch.arange(14.0).reshape(2, 7)
    assert torch.equal(velocity_changes(out), out[:, :6])


@pytest.mark.parametrize("model", [{}, REPORT_MODEL], ids=["default", "report"])
def test_network_widths_follow_the_contract(model):
    sim = learned(H=1, M=1, hidden=8, **model)
    state = batch([trajectory(12, seed=1)])
    graph = sim.graph_builder(state)
    out = sim.network_prediction(state, graph)
    assert out.shape == (12, sim.outputs.width)
    assert sim.outputs is node_outputs(sim.contacts.rest_decision, sim.inputs.engine_state)


@pytest.mark.parametrize("model", [{}, REPORT_MODEL], ids=["default", "report"])
def test_rollout_head_and_training_loss_read_the_same_step(model):
    torch.manual_seed(0)
    sim = learned(H=1, M=1, hidden=8, **model)
    lit = LitSimulator(sim, adam)
    state = batch([trajectory(10, seed=2), trajectory(6, seed=5)])
    graph = sim.graph_builder(state)
    calls = []
    original = sim.step
    sim.step = lambda *a: calls.append(a) or original(*a)
    vel, angvel, _, _ = sim.head(state, graph)
    lit.graph_losses(state, graph)
    assert len(calls) == 2  # one step function serves both
    step = original(state, graph)
    assert_close(step.vel, vel)
    assert_close(step.angvel, angvel)
    if sim.contacts.gravity_prior:
        assert step.reach is not None and step.reach.dtype == torch.bool
    else:
        assert step.reach is None
