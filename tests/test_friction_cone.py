"""The plane's tangential answer in Coulomb's cone (physgnn/models/friction.py): exact limits on
hand-built changes, and a frictionless sphere that slides on at constant velocity for any
weights."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import torch
from simdata import STATS, batch, learned, sliding

from physgnn.models.friction import friction_cone, sphere_friction
from physgnn.models.protocol import motion_of

G_DT = 9.81 * 0.1


def T(rows):
    return torch.tensor(rows, dtype=torch.float64)


def test_a_frictionless_plane_takes_no_tangential_answer_and_spins_nothing():
    floor = T([[0.0, 0, G_DT]])  # the ground's push on a sphere resting on it
    own, spin = T([[-0.4, 0.1, 0.2]]), T([[0.0, 3.0, 0]])
    vel, ang = friction_cone(floor, own, spin, T([0.0]))
    torch.testing.assert_close(vel, T([[0.0, 0, 0.2]]))  # the normal part is kept
    torch.testing.assert_close(ang, T([[0.0, 0, 0]]))


def test_friction_is_at_most_mu_times_the_planes_push():
    floor = T([[0.0, 0, G_DT], [0, 0, G_DT]])
    own = T([[-3.0, 4.0, 0], [1.0, 0, -0.5]])  # 5 m/s along the plane; 1 with a pull
    spin = T([[0.0, 1.0, 0], [0, 2.0, 0]])
    vel, ang = friction_cone(floor, own, spin, T([0.5, 0.5]))
    scale = 0.5 * G_DT / 5.0
    torch.testing.assert_close(vel[0], T([-3.0 * scale, 4.0 * scale, 0]))
    torch.testing.assert_close(ang[0], T([0.0, scale, 0]))  # ω's change scaled alike
    # the pull (−0.5 of the push) leaves a normal impulse of G_DT − 0.5, its cone 0.5 × that
    torch.testing.assert_close(vel[1, 0], torch.tensor(0.5 * (G_DT - 0.5)).double())
    within = T([[0.1, 0.2, 0]])  # inside the cone: untouched
    torch.testing.assert_close(friction_cone(floor[:1], within, spin[:1], T([0.5]))[0], within)


def test_a_spheres_friction_is_its_own_times_the_planes_over_the_planes_it_reaches():
    state = SimpleNamespace(
        material_params=T([[0.5, 0.6, 0, 0], [0.5, 0.2, 0, 0], [0.5, 1.0, 0, 0]]),
        plane_materials=T([[1.0, 1.0, 0, 0], [1.0, 0.5, 0, 0]]),
        radius=T([0.5, 0.5, 0.5]),
    )
    graph = SimpleNamespace(ps_index=torch.tensor([[0, 1, 1], [0, 0, 1]]))
    torch.testing.assert_close(sphere_friction(state, graph), T([0.6, 0.1, 0.0]))


@torch.no_grad()
def test_with_any_weights_a_frictionless_sphere_slides_on_at_its_speed():
    frictionless = np.array([[0.7, 0.0, 0.0, 0.0]], dtype=np.float32)
    plane = np.tile(np.array([[1.0, 0.0, 0.0, 0.0]], dtype=np.float32), (5, 1))
    traj = dataclasses.replace(sliding(), materials=frictionless, plane_materials=plane)
    state = batch([traj], t=0, H=0)
    # the rest decision off (its logit, random here, would stop the sphere) and the energy
    # guard (it cuts this answer too): the cone alone
    keys = dict(H=0, M=1, hidden=8, contact_passes=0, engine_state=True, rest_decision=False)
    keys |= dict(energy_guard=False)
    for seed in range(3):
        torch.manual_seed(seed)
        sim = learned(STATS, **keys).eval()
        last = [m for m in sim.network.decoder.modules() if isinstance(m, torch.nn.Linear)][-1]
        last.weight.normal_(0.0, 1.0)  # the own change starts at zero: give it one
        last.bias.normal_(0.0, 1.0)
        (vel, ang), (mean, _) = motion_of(sim(state))
        torch.testing.assert_close(vel[0, :2], torch.tensor([4.0, 0.0]))
        torch.testing.assert_close(mean[0, :2], torch.tensor([4.0, 0.0]))
        torch.testing.assert_close(ang[0], torch.zeros(3))
        sim.contacts = dataclasses.replace(sim.contacts, friction_cone=False)
        assert not torch.allclose(motion_of(sim(state))[0][0][0, :2], torch.tensor([4.0, 0.0]))
