"""A consistent rest (``model.contacts.rest_consistent``, physgnn/models/rest.py): the rest
decision stops no sphere whose own answer slides along the ground."""

import dataclasses
from types import SimpleNamespace

import torch
from simdata import STATS, batch, learned, sliding

from physgnn.models.protocol import motion_of
from physgnn.models.rest import still_along_the_ground


def test_the_rest_decision_stops_no_sphere_whose_answer_slides():
    state = SimpleNamespace(scene_dt=torch.full((3,), 0.1))
    answers = torch.tensor([[1.46, 0.0, 0.0], [0.0, 0.0, -0.981], [0.3, 0.3, -0.5]])
    # a sphere leaving a head-on along the ground is not still; one answered a frame of gravity
    # straight down (support left to the rest decision) and a slow creep are
    torch.testing.assert_close(
        still_along_the_ground(state, answers), torch.tensor([0, 1, 1]).bool()
    )


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
