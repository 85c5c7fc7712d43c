"""Hand-built trajectories and stats for the simulator / training tests (no pybullet)."""

from __future__ import annotations

import dataclasses
from functools import partial

import numpy as np
import torch
from torch_geometric.data import Batch

from physgnn.data.state import TrajectoryFrames
from physgnn.graph.builder import GraphBuilder
from physgnn.models.learned import LearnedSimulator
from physgnn.models.options import ContactHandling, ModelInputs
from physgnn.nn.epd import EncodeProcessDecode
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import Effects, Material, ground_plane, make_plane
from physgnn.physics.trajectory import Trajectory
from physgnn.training.layout import FLAT_KEYS

STATS = {
    "vel": {"mean": [0.1, -0.2, -3.0], "std": [1.0, 2.0, 4.0]},
    "angvel": {"mean": [0.0, 0.0, 0.0], "std": [0.5, 0.5, 0.5]},
    "delta_vel": {"mean": [0.0, 0.0, -0.9], "std": [0.2, 0.2, 1.5]},
    "delta_angvel": {"mean": [0.0, 0.0, 0.0], "std": [0.1, 0.1, 0.1]},
    "radius": {"mean": 0.5, "std": 0.1},
    "mass": {"mean": 2.0, "std": 0.5},
    "max_speed": 20.0,
    "n_pairs": 100,
}

# The report's model (conf/model/report.yaml) as keys of :func:`learned`, beyond H, M and
# hidden: vi connectivity, pp inputs [p_i − p_j, |p_i − p_j|], absolute mass among the node
# inputs, summed messages, 6 outputs, no contact or material inputs, no gravity prior, no rest
# decision. The constructor's defaults are the default model's (conf/model/baseline.yaml);
# tests/test_simulator.py checks both against the configs.
REPORT_MODEL = {
    "connectivity": "vi",
    "contact_features": False,
    "material_features": False,
    "gravity_prior": False,
    "layer_norm": False,
    "relative_pairs": False,
    "mass_ratio": False,
    "aggregation": "sum",
    "rest_decision": False,
    "contact_passes": 0,
    "pair_impulses": False,
    "plane_materials": False,
    "engine_state": False,
    "plane_floor": False,
    "plane_newton": False,
}
# The model keys of learned(): the flat layout's.
MODEL_KEYS = FLAT_KEYS


def learned(stats: dict = STATS, **keys) -> LearnedSimulator:
    """A LearnedSimulator from its model keys in the flat layout (``H=1, M=2, connectivity="vi",
    contact_passes=0``; :data:`MODEL_KEYS`): the network's, the graph
    builder's and the groups' keys are handed to them, the others to the simulator."""
    nodes: dict[str, dict] = {"network": {}, "graph": {}, "inputs": {}, "contacts": {}}
    for key in [k for k in keys if k in MODEL_KEYS]:
        node, name = MODEL_KEYS[key]
        nodes[node][name] = keys.pop(key)
    return LearnedSimulator(
        stats,
        network=partial(EncodeProcessDecode, **nodes["network"]),
        graph=GraphBuilder(**nodes["graph"]),
        inputs=ModelInputs(**nodes["inputs"]),
        contacts=ContactHandling(**nodes["contacts"]),
        **keys,
    )


def trajectory(
    n: int = 3, frames: int = 12, seed: int = 0, dt: float = 0.1, effects: Effects | None = None
) -> Trajectory:
    """``n`` spheres in ballistic flight above the ground (clipped at rest height), spinning at
    constant ω, inside 4 walls; deterministic in ``seed``."""
    rng = np.random.default_rng(seed)
    radius = rng.uniform(0.4, 0.6, n).astype(np.float32)
    mass = rng.uniform(1.0, 3.0, n).astype(np.float32)
    p0 = np.stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.uniform(2, 6, n)], 1)
    v0 = rng.normal(0, 1, (n, 3))
    w0 = rng.normal(0, 1, (n, 3))
    t = np.arange(frames)[:, None, None] * dt
    pos = p0 + v0 * t + 0.5 * np.array([0, 0, -9.81]) * t**2
    pos[..., 2] = np.maximum(pos[..., 2], radius)
    quat = Q.exp(torch.as_tensor(w0 * t, dtype=torch.float32)).numpy()
    vel = np.gradient(pos, dt, axis=0)
    angvel = np.broadcast_to(w0, (frames, n, 3))
    walls = [make_plane((x, 0, 5), (-np.sign(x), 0, 0), (0, 1, 0), 5, 5) for x in (-5, 5)]
    walls += [make_plane((0, y, 5), (0, -np.sign(y), 0), (1, 0, 0), 5, 5) for y in (-5, 5)]
    return Trajectory(
        name=f"hand_{seed}",
        pos=pos.astype(np.float32),
        quat=quat.astype(np.float32),
        vel=vel.astype(np.float32),
        angvel=np.ascontiguousarray(angvel, dtype=np.float32),
        radius=radius,
        mass=mass,
        material=np.zeros(n, dtype=np.int64),
        planes=np.stack([ground_plane(), *walls]),
        plane_kind=np.array([0, 1, 1, 1, 1], dtype=np.int64),
        materials=Material().as_array()[None],
        dt=dt,
        effects=effects or Effects(),
        attrs={"seed": seed},
    )


def batch(trajs: list[Trajectory], t: int = 3, H: int = 2):
    """A PyG batch of the states at frame ``t`` of several trajectories."""
    return Batch.from_data_list([TrajectoryFrames(tr).state(t, H) for tr in trajs])


def sliding(speed: float = 4.0, frames: int = 3) -> Trajectory:
    """One sphere of :func:`trajectory` resting on the ground and sliding along x at ``speed``
    (m/s) without spin."""
    traj = trajectory(1, frames=frames, seed=0)
    t = np.arange(frames)[:, None, None] * traj.dt
    pos = np.array([[0.0, 0.0, float(traj.radius[0])]]) + np.array([[speed, 0, 0]]) * t
    vel = np.broadcast_to(np.array([[speed, 0, 0]]), pos.shape)
    return dataclasses.replace(
        traj,
        pos=pos.astype(np.float32),
        vel=np.ascontiguousarray(vel, dtype=np.float32),
        angvel=np.zeros_like(traj.angvel),
    )


def head_on(gap: float = 0.1, speed: float = 4.0, frames: int = 4, dt: float = 0.1) -> Trajectory:
    """Two spheres of :func:`trajectory` 50 m up (no plane in reach) closing head-on at
    ``speed`` m/s each, ``gap`` m apart at frame 0, in free flight (the engine's velocities)."""
    traj = trajectory(2, frames=frames, seed=0, dt=dt)
    t = np.arange(frames)[:, None, None] * dt
    reach = float(traj.radius.sum()) + gap
    p0 = np.array([[-reach / 2, 0, 50], [reach / 2, 0, 50]])
    v0 = np.array([[speed, 0, 0], [-speed, 0, 0]])
    pos = p0 + v0 * t + 0.5 * np.array([0, 0, -9.81]) * t**2
    vel = v0 + np.array([0, 0, -9.81]) * t
    return dataclasses.replace(traj, pos=pos.astype(np.float32), vel=vel.astype(np.float32))
