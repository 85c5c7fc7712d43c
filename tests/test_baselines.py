"""Trivial baselines (physgnn.models.baselines) through the rollout engine."""

import numpy as np
import torch
from torch_geometric.data import Batch

from physgnn.data.state import TrajectoryFrames
from physgnn.models.baselines import GravityOnlySimulator, StaticSimulator
from physgnn.physics.scene import Effects, ground_plane
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout

DT, G = 0.1, 9.81


def flight(p0, v0, w0=(0.0, 0.0, 0.0), frames=30, effects=None, name="fall"):
    """One sphere; only frame 0 (position, engine velocities) matters for an H = 0 rollout."""
    pos = np.broadcast_to(np.asarray(p0, np.float32), (frames, 1, 3)).copy()
    quat = np.zeros((frames, 1, 4), np.float32)
    quat[..., 0] = 1
    return Trajectory(
        name=name,
        pos=pos,
        quat=quat,
        vel=np.broadcast_to(np.asarray(v0, np.float32), (frames, 1, 3)).copy(),
        angvel=np.broadcast_to(np.asarray(w0, np.float32), (frames, 1, 3)).copy(),
        radius=np.full(1, 0.5, np.float32),
        mass=np.ones(1, np.float32),
        material=np.zeros(1, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=np.zeros((1, 4), np.float32),
        dt=DT,
        effects=effects or Effects(),
    )


def test_gravity_only_reproduces_free_fall():
    p0, v0 = np.array([1.0, 2.0, 200.0]), np.array([3.0, 0.0, 4.0])
    (res,) = rollout(GravityOnlySimulator(), [flight(p0, v0)], dtype=torch.float64)
    k = np.arange(30.0)[:, None]
    g = np.array([0, 0, -G])
    # Semi-implicit Euler: v_k = v_0 + k·g·dt, p_k = p_0 + k·dt·v_0 + g·dt²·k(k+1)/2 ...
    discrete = p0 + k * DT * v0 + g * DT**2 * k * (k + 1) / 2
    np.testing.assert_allclose(res.pos[:, 0], discrete, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(res.vel[1:, 0], v0 + k[1:] * DT * g, rtol=1e-5, atol=1e-4)
    # ... which is the analytic p_0 + v_0·t + g·t²/2 plus the first-order term g·dt·t/2.
    t = k * DT
    analytic = p0 + v0 * t + g * t**2 / 2
    np.testing.assert_allclose(res.pos[:, 0] - analytic, g * DT * t / 2, atol=1e-4)
    assert res.diverged_at is None and res.n_frames == 30
    # In float32 the velocities come from differences of rounded positions near 200 m
    # (ulp 1.5e-5 m, / dt): after 30 frames the drift stays below 1 mm.
    (res32,) = rollout(GravityOnlySimulator(), [flight(p0, v0)])
    assert np.abs(res32.pos[:, 0] - discrete).max() < 1e-3


def test_gravity_effect_off_means_constant_velocity_and_spin_is_kept():
    (res,) = rollout(
        GravityOnlySimulator(),
        [flight([0, 0, 5], [1.0, 0, 0], w0=(0, 0, 1.0), effects=Effects(gravity=False))],
    )
    np.testing.assert_allclose(res.pos[-1, 0], [29 * DT, 0, 5], rtol=1e-5)
    angle = 2 * np.arctan2(np.linalg.norm(res.quat[-1, 0, 1:]), res.quat[-1, 0, 0])
    assert angle > 1.0  # about 29·0.1 rad of spin about z (first-order integrator)
    np.testing.assert_allclose(res.quat[-1, 0, 1:3], 0.0, atol=1e-6)


def test_static_keeps_everything_in_place():
    traj = flight([0, 0, 5], [1.0, 2.0, 3.0], w0=(1.0, 0, 0))
    (res,) = rollout(StaticSimulator(), [traj])
    np.testing.assert_array_equal(res.pos, np.broadcast_to(traj.pos[0], res.pos.shape))
    np.testing.assert_allclose(res.quat, np.broadcast_to(traj.quat[0], res.quat.shape))
    np.testing.assert_array_equal(res.vel[1:], 0.0)


def test_per_scene_gravity_in_one_batch():
    on = flight([0, 0, 5], [0.0, 0, 0], name="on")
    off = flight([0, 0, 5], [0.0, 0, 0], effects=Effects(gravity=False), name="off")
    states = [TrajectoryFrames(t).state(0, 0) for t in (on, off)]
    vel, angvel = GravityOnlySimulator()(Batch.from_data_list(states))
    torch.testing.assert_close(vel, torch.tensor([[0, 0, -G * DT], [0, 0, 0]]))
    torch.testing.assert_close(angvel, torch.zeros(2, 3))
    assert StaticSimulator.H == GravityOnlySimulator.history == 0
