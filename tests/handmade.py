"""Hand-built states, scenes and trajectories shared by the graph, contact and data tests:
one ``SceneState`` with planes (:func:`make_state`), a wall (:data:`WALL_ROW`), a seeded batch
of scenes (:func:`random_batch`), a batch of spheres in uniform motion (:func:`scene`), a
contact-aware model (:func:`make`), linear trajectories (:func:`linear_traj`)."""

from __future__ import annotations

import numpy as np
import torch
from simdata import learned
from torch_geometric.data import Batch

from physgnn.data.state import SceneState, TrajectoryFrames
from physgnn.models.learned import LearnedSimulator
from physgnn.physics.scene import GROUND, WALL, Effects, Material, ground_plane, make_plane
from physgnn.physics.trajectory import Trajectory


def make_state(pos, vel=None, radius=0.5, planes=(), kinds=(), dt=0.125, effects=None):
    """One SceneState: ground (row 0) + the given plane rows; vel ``[N, 3]`` (H = 0)."""
    pos = torch.as_tensor(pos, dtype=torch.float32).reshape(-1, 3)
    n = pos.shape[0]
    vel = torch.zeros(n, 3) if vel is None else torch.as_tensor(vel, dtype=torch.float32)
    radius = torch.as_tensor(radius, dtype=torch.float32).expand(n).clone()
    rows = np.stack([ground_plane(), *planes]) if len(planes) else ground_plane()[None]
    effects = [True] * 5 if effects is None else effects
    return SceneState(
        pos=pos,
        quat=torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
        vel=vel.reshape(n, 1, 3),
        angvel=torch.zeros(n, 1, 3),
        radius=radius,
        mass=torch.ones(n),
        material=torch.zeros(n, dtype=torch.long),
        planes=torch.as_tensor(rows, dtype=torch.float32),
        plane_kind=torch.tensor([GROUND, *kinds], dtype=torch.long),
        plane_batch=torch.zeros(len(rows), dtype=torch.long),
        dt=torch.tensor([dt]),
        effects=torch.tensor([effects], dtype=torch.bool),
    )


# A wall x = 4 facing −x, spanning y ∈ [−2, 2] and z ∈ [0, 6] (half lengths 2 and 3).
WALL_ROW = make_plane((4, 0, 3), (-1, 0, 0), (0, 1, 0), 2.0, 3.0)


def random_batch(seed: int, scenes: int = 5, host: bool = True) -> Batch:
    """``scenes`` scenes of 1 to 13 spheres (radius 0.4) at random, every second one with
    :data:`WALL_ROW`; ``host``: with the ``host_sizes`` a data loader gives."""
    gen = torch.Generator().manual_seed(seed)
    states = []
    for s in range(scenes):
        n = int(torch.randint(1, 14, (1,), generator=gen))
        pos = torch.rand(n, 3, generator=gen) * torch.tensor([5.0, 3.0, 4.0])
        vel = torch.randn(n, 3, generator=gen)
        walls = dict(planes=[WALL_ROW], kinds=[WALL]) if s % 2 else {}
        states.append(make_state(pos, vel, radius=0.4, **walls))
    batch = Batch.from_data_list(states)
    if host:
        batch.host_sizes = (
            tuple(s.pos.shape[0] for s in states),
            tuple(s.planes.shape[0] for s in states),
        )
    return batch


DT = 0.1


MATERIALS = np.array([[0.7, 0.5, 0.005, 0.005], [0.3, 0.9, 0.02, 0.02]], np.float32)


def scene(pos, vel, radius, mass=None, material=None, planes=None, kinds=None, frames=4):
    """The state at the last of ``frames`` frames of spheres moving at constant ``vel``, that
    frame at ``pos`` (finite differences give exactly ``vel``)."""
    pos, vel = np.asarray(pos, np.float64), np.asarray(vel, np.float64)
    n = len(pos)
    t = (np.arange(frames) - (frames - 1))[:, None, None] * DT
    traj = Trajectory(
        name="hand",
        pos=(pos + vel * t).astype(np.float32),
        quat=np.tile(np.array([1.0, 0, 0, 0], np.float32), (frames, n, 1)),
        vel=np.broadcast_to(vel, (frames, n, 3)).astype(np.float32),
        angvel=np.zeros((frames, n, 3), np.float32),
        radius=np.asarray(radius, np.float32),
        mass=np.asarray(mass if mass is not None else [1.0] * n, np.float32),
        material=np.asarray(material if material is not None else [0] * n, np.int64),
        planes=np.stack(planes) if planes is not None else ground_plane()[None],
        plane_kind=np.asarray(kinds if kinds is not None else [0], np.int64),
        materials=MATERIALS,
        dt=DT,
        effects=Effects(),
    )
    return Batch.from_data_list([TrajectoryFrames(traj).state(frames - 1, 2)])


def ballistic(state):
    """``state`` with velocity histories of free flight ending at its current ``v_t``."""
    back = torch.arange(state.vel.shape[1], dtype=torch.float32)[None, :, None]
    state.vel = state.vel[:, :1] + back * torch.tensor([0.0, 0.0, 9.81 * DT])
    return state


def make(**kwargs) -> LearnedSimulator:
    torch.manual_seed(0)
    args = dict(H=2, M=2, hidden=16, contact_features=True, material_features=True)
    return learned(**(args | kwargs))


def linear_traj(t=5, n=2, v=(1.0, -2.0, 0.5), dt=0.1, name="lin") -> Trajectory:
    """Spheres moving at constant velocity ``v``, not rotating."""
    v = np.asarray(v, dtype=np.float64)
    p0 = np.arange(n * 3, dtype=np.float64).reshape(n, 3) + 5.0
    pos = p0 + v * (np.arange(t) * dt)[:, None, None]
    quat = np.tile([1.0, 0, 0, 0], (t, n, 1))
    return Trajectory(
        name=name,
        pos=pos.astype(np.float32),
        quat=quat.astype(np.float32),
        vel=np.broadcast_to(v, (t, n, 3)).astype(np.float32),
        angvel=np.zeros((t, n, 3), np.float32),
        radius=np.full(n, 0.5, np.float32),
        mass=np.array([1.0, 3.0][:n] + [1.0] * (n - 2), np.float32),
        material=np.zeros(n, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.array([0]),
        materials=Material().as_array()[None],
        dt=dt,
        effects=Effects(rotation=False),
        attrs={
            "seed": 7,
            "scene": "lin_scene",
            "scene_config": "name: lin_scene\n",
            "substeps": 20,
            "engine": "pybullet test",
            "gravity": [0.0, 0.0, -9.81],
        },
    )
