"""Core physics containers: integrator, energy, scene validation, SceneState batching."""

import math

import numpy as np
import pytest
import torch
from torch.testing import assert_close
from torch_geometric.data import Batch

from physgnn.data.state import TrajectoryFrames
from physgnn.physics import quaternion as Q
from physgnn.physics.energy import scene_energy, scene_weight, sphere_energy
from physgnn.physics.integrator import euler_step
from physgnn.physics.scene import Effects, Scene, SceneError, ground_plane, make_plane
from physgnn.physics.trajectory import Trajectory


def test_euler_step_position_is_semi_implicit():
    pos = torch.tensor([[0.0, 0.0, 10.0]])
    vel_next = torch.tensor([[1.0, -2.0, -0.981]])
    p, q = euler_step(pos, Q.identity(1), vel_next, torch.zeros(1, 3), 0.1)
    assert_close(p, torch.tensor([[0.1, -0.2, 10.0 - 0.0981]]))
    assert_close(q, Q.identity(1))


def test_euler_step_rotation_about_z_matches_exact_rotation():
    omega = torch.tensor([[0.0, 0.0, 0.5]])
    q = Q.identity(1)
    for _ in range(100):
        _, q = euler_step(torch.zeros(1, 3), q, torch.zeros(1, 3), omega, 0.01)
    # The first-order update has a per-step angle error of O((ω dt)³): tiny here.
    angle = 2 * math.atan2(q[0, 3].item(), q[0, 0].item())
    assert angle == pytest.approx(0.5, abs=1e-6)
    assert_close(q.norm(dim=-1), torch.ones(1))


def test_euler_step_rotation_off_keeps_quaternions_bit_identical():
    q = Q.normalize(torch.randn(3, 4))
    rotate = torch.tensor([True, False, False])
    _, q_next = euler_step(torch.zeros(3, 3), q, torch.zeros(3, 3), torch.ones(3, 3), 0.1, rotate)
    assert torch.equal(q_next[1:], q[1:])
    assert not torch.equal(q_next[0], q[0])
    _, q_off = euler_step(torch.zeros(3, 3), q, torch.zeros(3, 3), torch.ones(3, 3), 0.1, False)
    assert torch.equal(q_off, q)


def test_energy_zero_at_rest_on_ground_and_hand_values():
    radius = torch.tensor([0.5, 1.0])
    mass = torch.tensor([2.0, 3.0])
    pos = torch.tensor([[0.0, 0.0, 0.5], [0.0, 0.0, 11.0]])
    vel = torch.tensor([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    e = sphere_energy(pos, vel, mass, radius)
    assert_close(e, torch.tensor([0.0, 0.5 * 3 * 25 + 3 * 9.81 * 10]))
    batch = torch.tensor([0, 1])
    assert_close(scene_energy(pos, vel, mass, radius, batch, 2), e)
    assert_close(scene_weight(mass, batch, 2), torch.tensor([2 * 9.81, 3 * 9.81]))


def _scene(**changes):
    n = 2
    fields = dict(
        name="t",
        radius=np.ones(n, np.float32),
        mass=np.ones(n, np.float32),
        material=np.zeros(n, np.int64),
        pos=np.zeros((n, 3), np.float32),
        quat=np.tile(np.array([1, 0, 0, 0], np.float32), (n, 1)),
        vel=np.zeros((n, 3), np.float32),
        angvel=np.zeros((n, 3), np.float32),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=np.zeros((1, 4), np.float32),
        dt=0.1,
        n_frames=10,
    )
    fields.update(changes)
    return Scene(**fields)


@pytest.mark.parametrize(
    "changes, message",
    [
        (dict(radius=np.array([1.0, -1.0], np.float32)), "radius must be > 0"),
        (dict(mass=np.array([1.0, 0.0], np.float32)), "mass must be > 0"),
        (dict(radius=np.zeros(0, np.float32)), "no sphere"),
        (dict(material=np.array([0, 3])), "material id out of range"),
        (dict(pos=np.full((2, 3), np.nan, np.float32)), "pos contains NaN"),
        (dict(dt=0.0), "dt > 0"),
    ],
)
def test_scene_validation_names_the_problem(changes, message):
    with pytest.raises(SceneError, match=message):
        _scene(**changes).validate()


def test_plane_rows_and_effects():
    wall = make_plane((5, 0, 1), (-2, 0, 0), (0, 1, 0), 5.0, 1.0)
    assert_close(torch.from_numpy(wall[3:6]), torch.tensor([-1.0, 0.0, 0.0]))
    with pytest.raises(SceneError, match="not perpendicular"):
        make_plane((0, 0, 0), (0, 0, 1), (0, 1, 1), 1.0, 1.0)
    assert Effects.from_dict({"rotation": False}).rotation is False
    with pytest.raises(SceneError, match="unknown effect"):
        Effects.from_dict({"magnetism": True})


def _trajectory(t_frames=5, n=2):
    pos = np.zeros((t_frames, n, 3), np.float32)
    pos[:, :, 2] = np.arange(t_frames)[:, None] * np.arange(1.0, n + 1)  # v_z = 10, 20, …
    quat = np.tile(np.array([1, 0, 0, 0], np.float32), (t_frames, n, 1))
    vel0 = np.zeros((t_frames, n, 3), np.float32)
    vel0[0, :, 0] = 7.0  # engine velocity at frame 0 becomes v_0
    return Trajectory(
        name="t",
        pos=pos,
        quat=quat,
        vel=vel0,
        angvel=np.zeros_like(vel0),
        radius=np.ones(n, np.float32),
        mass=np.ones(n, np.float32),
        material=np.zeros(n, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=np.zeros((1, 4), np.float32),
        dt=0.1,
    )


def test_trajectory_frames_history_and_targets():
    frames = TrajectoryFrames(_trajectory())
    s = frames.state(1, 1)
    # history latest first: [v_1, v_0]; v_0 is the engine's initial velocity.
    assert_close(s.vel[:, 0], torch.tensor([[0.0, 0.0, 10.0], [0.0, 0.0, 20.0]]))
    assert_close(s.vel[:, 1], torch.tensor([[7.0, 0.0, 0.0], [7.0, 0.0, 0.0]]))
    assert_close(s.target_vel, torch.tensor([[0.0, 0.0, 10.0], [0.0, 0.0, 20.0]]))
    assert not hasattr(frames.state(4, 0), "target_vel") or frames.state(4, 0).target_vel is None
    with pytest.raises(IndexError):
        frames.state(0, 1)


def test_scene_states_batch_into_one_graph():
    a, b = TrajectoryFrames(_trajectory(n=2)), TrajectoryFrames(_trajectory(n=3))
    batch = Batch.from_data_list([a.state(2, 1), b.state(2, 1)])
    assert batch.num_graphs == 2
    assert batch.pos.shape == (5, 3)
    assert batch.vel.shape == (5, 2, 3)
    assert batch.plane_batch.tolist() == [0, 1]
    assert batch.batch.tolist() == [0, 0, 1, 1, 1]
    assert_close(batch.scene_dt, torch.full((5,), 0.1))
    assert batch.effects.shape == (2, 5)
