"""A consistent rest (``model.contacts.rest_consistent``, physgnn/models/rest.py): the rest
decision stops no sphere whose own answer slides along the ground faster than friction could
stop."""

import dataclasses
from types import SimpleNamespace

import torch
from simdata import STATS, batch, learned, sliding

from physgnn.models.protocol import motion_of
from physgnn.models.rest import still_along_the_ground


def test_the_rest_decision_stops_no_sphere_friction_could_not_stop():
    # μ 0.5, 0.5, 0.5, 0 (frictionless) and 0.05
    state = SimpleNamespace(
        scene_dt=torch.full((5,), 0.1),
        material_params=torch.tensor([[0.5, m, 0, 0] for m in (0.5, 0.5, 0.5, 0.0, 0.05)]),
    )
    answers = torch.tensor(
        [
            [1.46, 0.0, 0.0],  # leaving a head-on along the ground: not still
            [0.0, 0.0, -0.981],  # a frame of gravity straight down: support left to the rest
            [0.3, 0.3, -0.5],  # slow enough for friction (0.49 m/s at μ ≥ 0.5)
            [0.3, 0.0, 0.0],  # on a frictionless contact nothing takes its speed
            [0.0, 0.005, 0.0],  # below the rest speed: stopped at any friction
        ]
    )
    still = still_along_the_ground(state, answers, rest_speed=0.01)
    torch.testing.assert_close(still, torch.tensor([0, 1, 1, 0, 1]).bool())
    slow = still_along_the_ground(state, torch.tensor([[0.06, 0, 0]] * 5), rest_speed=0.01)
    torch.testing.assert_close(slow, torch.tensor([1, 1, 1, 0, 0]).bool())  # μ·g·dt 0.049


@torch.no_grad()
def test_with_a_rest_logit_that_disagrees_a_sliding_sphere_keeps_its_answer():
    traj = sliding()
    state = batch([traj], t=0, H=0)
    keys = dict(H=0, M=1, hidden=8, contact_passes=0, engine_state=True, energy_guard=False)
    torch.manual_seed(0)
    sim = learned(STATS, **keys).eval()
    last = [m for m in sim.network.decoder.modules() if isinstance(m, torch.nn.Linear)][-1]
    rest = sim.outputs.slice("rest").start
    last.bias[rest] = 50.0  # the logit: at rest, whatever the inputs
    answer = motion_of(sim(state))[0][0][0]
    assert float(answer[:2].norm()) > 3.0  # its answer kept: it slides on
    sim.contacts = dataclasses.replace(sim.contacts, rest_consistent=False)
    torch.testing.assert_close(motion_of(sim(state))[0][0][0], torch.zeros(3))  # stopped
