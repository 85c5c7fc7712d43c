"""The simulator's view of scenes at one frame, as a PyG ``Data`` that batches many scenes.

One :class:`SceneState` is one scene; ``Batch.from_data_list`` (or the PyG DataLoader) joins
many into one disconnected graph: node tensors are concatenated, ``batch`` says the scene of
each sphere, ``plane_batch`` the scene of each plane, and ``num_graphs`` the scene count.
Graph edges are *not* stored here: they depend on the (noisy, predicted) state and are
rebuilt from it at every step by :mod:`physgnn.graph.builder`.
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from torch_geometric.data import Data

from physgnn.physics.kinematics import finite_difference_velocities, history
from physgnn.physics.scene import EFFECT_NAMES, Effects
from physgnn.physics.trajectory import Trajectory

# Per-sphere fields of a SceneState (first dimension N); the rest are per plane or per scene.
NODE_KEYS = (
    "pos",
    "quat",
    "vel",
    "angvel",
    "radius",
    "mass",
    "material",
    "material_params",
    "batch",
    "target_vel",
    "target_angvel",
    "target_mean_vel",
    "target_mean_angvel",
)
SCENE_KEYS = ("planes", "plane_kind", "plane_materials", "plane_batch", "dt", "effects", "ptr")


class SceneState(Data):
    """Fields (N spheres, S planes, H history; after batching, B scenes):

    - ``pos [N, 3]``, ``quat [N, 4]`` (w, x, y, z)
    - ``vel [N, H+1, 3]``, ``angvel [N, H+1, 3]``: latest first (``vel[:, 0]`` is ``v_t``)
    - ``radius [N]``, ``mass [N]``, ``material [N]`` (long), ``material_params [N, 4]``: the
      sphere's material row (restitution, lateral, rolling, spinning friction)
    - ``planes [S, 11]``, ``plane_kind [S]`` (long), ``plane_batch [S]`` (scene of each plane)
    - ``plane_materials [S, 4]``: each plane's coefficients in the order of ``material_params``
      (restitution ``e_p`` first: a sphere of ``e`` bounces off it with ``e·e_p``)
    - ``dt [B]``, ``effects [B, 5]`` (bool, order of ``scene.EFFECT_NAMES``)
    - optional targets ``target_vel [N, 3]``, ``target_angvel [N, 3]`` (``v_{t+1}``, ``ω_{t+1}``);
      with the engine state (:class:`TrajectoryFrames`) also ``target_mean_vel [N, 3]``,
      ``target_mean_angvel [N, 3]``: the frame's mean motion ``(p_{t+1} − p_t)/dt`` and
      ``log(q_{t+1} ⊗ q_t⁻¹)/dt``
    - optional ``future_pos [N, K+1, 3]``, ``future_angvel [N, K+1, 3]``: ``p_{t+1..t+K+1}``,
      the mean ``ω̄_{t+1..t+K+1}``, the targets of a push-forward of up to K steps; with the
      engine state also ``future_vel``, ``future_end_angvel [N, K+1, 3]``, the engine's
      end-of-frame velocities
    """

    @property
    def scene_dt(self) -> torch.Tensor:
        """Frame interval of every sphere's scene, ``[N]``."""
        return self.dt[scene_of_sphere(self)]


def scene_of_sphere(state) -> torch.Tensor:
    """``[N]`` long: the scene of every sphere of a state, a batch (its ``batch``) or a single
    scene (zeros)."""
    batch = getattr(state, "batch", None)
    if batch is None:
        return torch.zeros(state.pos.shape[0], dtype=torch.long, device=state.pos.device)
    return batch.long()


def host_sizes(state) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """``(spheres per scene, planes per scene)`` as host ints, the layout the graph builder
    writes its candidates from: ``state.host_sizes`` where the code that made the batch kept
    it (a tuple of two tuples), the shapes of a single scene, else counted on the device and
    read back once (a sync on a GPU)."""
    sizes = getattr(state, "host_sizes", None)
    if sizes is not None:
        return sizes
    if getattr(state, "batch", None) is None:
        return (state.pos.shape[0],), (state.planes.shape[0],)
    return _layout(state, state.dt.shape[0])


def layout_of(states: list) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """:func:`host_sizes` of the batch of ``states`` (single scenes), from their shapes."""
    return tuple(s.pos.shape[0] for s in states), tuple(s.planes.shape[0] for s in states)


def _layout(state, scenes: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    batch, plane_batch = scene_of_sphere(state), state.plane_batch.long()
    spheres = batch.new_zeros(scenes).scatter_add_(0, batch, torch.ones_like(batch))
    planes = batch.new_zeros(scenes).scatter_add_(0, plane_batch, torch.ones_like(plane_batch))
    counts = torch.cat([spheres, planes]).tolist()  # the one read-back
    return tuple(counts[:scenes]), tuple(counts[scenes:])


def effects_tensor(effects: Effects) -> torch.Tensor:
    """``[1, 5]`` bool row in the order of ``EFFECT_NAMES``."""
    return torch.tensor([[getattr(effects, k) for k in EFFECT_NAMES]], dtype=torch.bool)


def _float32(a) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.float32))


def has_engine_velocities(traj: Trajectory) -> bool:
    """Whether ``traj`` holds an engine's end-of-frame velocities (its ``engine`` attribute, which
    generation writes, or ``analytic`` for the exact ballistic seeds of the eval): data with
    positions only (the GNS and LagrangeBench imports,
    :meth:`Trajectory.from_arrays`) has finite differences there."""
    return bool(traj.attrs.get("engine"))


class TrajectoryFrames:
    """A trajectory as float32 tensors with its velocities precomputed.

    ``state(t, h)`` is the :class:`SceneState` at frame ``t`` with ``h + 1`` velocities of
    history (needs ``t ≥ h``) and, when ``t + 1`` exists, the targets of frame ``t + 1``; with
    ``future=K`` also the K + 1 next positions and angular velocities (needs ``t + K + 1 < T``).

    The state's velocities (``vel``, ``angvel`` ``[T, N, 3]``): finite differences
    (``engine_state`` False, the report's state), or the engine's end-of-frame velocities that
    the dataset stores (``engine_state`` True, where the trajectory has them:
    :func:`has_engine_velocities`; else finite differences). ``mean_vel``, ``mean_angvel``: the
    finite differences, each frame's mean motion (the same tensors for a finite-difference
    state).
    """

    def __init__(self, traj: Trajectory, engine_state: bool = False):
        self.traj = traj
        self.pos, self.quat = _float32(traj.pos), _float32(traj.quat)
        self.mean_vel, self.mean_angvel = finite_difference_velocities(
            self.pos, self.quat, _float32(traj.vel[0]), _float32(traj.angvel[0]), traj.dt
        )
        self.engine_state = bool(engine_state)
        if self.engine_state and has_engine_velocities(traj):
            self.vel, self.angvel = _float32(traj.vel), _float32(traj.angvel)
        else:
            self.vel, self.angvel = self.mean_vel, self.mean_angvel
        self.static = dict(
            radius=_float32(traj.radius),
            mass=_float32(traj.mass),
            material=torch.as_tensor(np.asarray(traj.material), dtype=torch.long),
            material_params=_float32(np.asarray(traj.materials).reshape(-1, 4)[traj.material]),
            planes=_float32(traj.planes),
            plane_materials=_float32(traj.plane_coefficients),
            plane_kind=torch.as_tensor(np.asarray(traj.plane_kind), dtype=torch.long),
            plane_batch=torch.zeros(len(traj.planes), dtype=torch.long),
            dt=torch.tensor([traj.dt], dtype=torch.float32),
            effects=effects_tensor(traj.effects),
        )

    @property
    def n_frames(self) -> int:
        return int(self.pos.shape[0])

    def state(self, t: int, h: int, future: int = 0) -> SceneState:
        s = SceneState(
            pos=self.pos[t].clone(),
            quat=self.quat[t].clone(),
            vel=history(self.vel, t, h),
            angvel=history(self.angvel, t, h),
            **self.static,
        )
        if t + 1 < self.n_frames:
            s.target_vel = self.vel[t + 1].clone()
            s.target_angvel = self.angvel[t + 1].clone()
            if self.engine_state:
                s.target_mean_vel = self.mean_vel[t + 1].clone()
                s.target_mean_angvel = self.mean_angvel[t + 1].clone()
        if future > 0:
            ahead = slice(t + 1, t + future + 2)
            s.future_pos = self.pos[ahead].transpose(0, 1).contiguous()
            s.future_angvel = self.mean_angvel[ahead].transpose(0, 1).contiguous()
            if self.engine_state:
                s.future_vel = self.vel[ahead].transpose(0, 1).contiguous()
                s.future_end_angvel = self.angvel[ahead].transpose(0, 1).contiguous()
        return s


def subset_state(state, mask: torch.Tensor):
    """A shallow copy of ``state`` (one scene or a Batch) with only the spheres of ``mask [N]``.

    Planes, ``dt`` and ``effects`` are kept whole (every scene stays, even if it lost all its
    spheres); ``batch`` keeps the scene ids and ``ptr`` is recomputed.
    """
    n = state.pos.shape[0]
    sub = copy.copy(state)
    for key in state.keys():
        value = state[key]
        if not torch.is_tensor(value) or key in SCENE_KEYS:
            continue
        if key in NODE_KEYS or (value.dim() > 0 and value.shape[0] == n):
            sub[key] = value[mask]
    if getattr(state, "host_sizes", None) is not None:
        sub.host_sizes = None  # the layout changed
    if getattr(state, "ptr", None) is not None:
        counts = torch.bincount(scene_of_sphere(state)[mask], minlength=state.dt.shape[0])
        sub.ptr = torch.cat([counts.new_zeros(1), torch.cumsum(counts, 0)])
    return sub
