"""The state of one rollout on its device: the active scenes as one batch, integrated in place
(:class:`SceneBatch`, :func:`one_step`), and the frames recorded (:class:`FrameRecord`), which
reach the host once, at the end (:func:`physgnn.rollout.rollout`).
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from torch_geometric.data import Batch

from physgnn.data.state import SceneState, TrajectoryFrames, layout_of
from physgnn.models.profiling import StepTimer
from physgnn.models.protocol import motion_of
from physgnn.physics import integrator
from physgnn.physics.scene import EFFECT_NAMES

ROTATION = EFFECT_NAMES.index("rotation")
_FLOAT_KEYS = (
    "pos",
    "quat",
    "vel",
    "angvel",
    "radius",
    "mass",
    "material_params",
    "planes",
    "plane_materials",
    "dt",
)
_RECORDED = {"pos": 3, "quat": 4, "vel": 3, "angvel": 3}


class SceneBatch:
    """The active scenes of a rollout as one batched SceneState, rebuilt when scenes stop.

    ``pos, quat, vel, angvel`` are the batch's own tensors, updated in place by :meth:`step`;
    the per-sphere constants of a step (dt, rotation flags, speed bound) are cached here.
    """

    def __init__(self, states: list[SceneState], speed_bound: torch.Tensor, device, dtype):
        self.states = states  # per scene, kept for the rebuilds
        self.speed_bound = speed_bound  # [B] per scene
        self.device, self.dtype = device, dtype
        self.active = list(range(len(states)))
        self._build(states)

    def _build(self, states: list[SceneState]) -> None:
        if not states:
            self.batch = None
            return
        b = Batch.from_data_list(states)
        b.host_sizes = layout_of(states)  # graph builds then read no size back
        b = b.to(self.device)
        for key in _FLOAT_KEYS:
            b[key] = b[key].to(self.dtype)
        self.batch = b
        self.pos, self.quat, self.vel, self.angvel = b.pos, b.quat, b.vel, b.angvel
        self.node_batch, self.num_graphs = b.batch, b.num_graphs
        self.dt = b.dt[b.batch]  # [N]
        rot = b.effects[b.batch, ROTATION]
        self.rotate = True if bool(rot.all()) else (False if not bool(rot.any()) else rot)
        self.bound = self.speed_bound[self.active].to(self.device)[b.batch]  # [N]

    def keep(self, keep: list[int]) -> None:
        """Keep the active scenes at positions ``keep`` with their current dynamic state."""
        ptr = self.batch.ptr.tolist()
        states = []
        for pos_in_batch in keep:
            lo, hi = ptr[pos_in_batch], ptr[pos_in_batch + 1]
            s = copy.copy(self.states[self.active[pos_in_batch]])
            for key in ("pos", "quat", "vel", "angvel"):
                s[key] = getattr(self, key)[lo:hi]
            states.append(s)
        self.active = [self.active[k] for k in keep]
        self._build(states)

    def step(self, answer: tuple, max_pos: float, hold=None) -> list[bool] | None:
        """Integrate one frame in place (:func:`physgnn.physics.integrator.step`) from a
        simulator's ``answer`` (:func:`~physgnn.models.protocol.motion_of`).

        Returns None when every scene is fine, else a per-scene list: diverged?
        """
        (vel_next, angvel_next), mean = motion_of(answer)
        pos_next, quat_next, vel, angvel = integrator.step(
            self.pos,
            self.quat,
            self.vel,
            self.angvel,
            vel_next,
            angvel_next,
            self.dt,
            self.rotate,
            hold,
            mean,
        )
        for own, new in (
            (self.pos, pos_next),
            (self.quat, quat_next),
            (self.vel, vel),
            (self.angvel, angvel),
        ):
            own.copy_(new)
        # One reduction: a NaN or inf anywhere in a row makes its sum non-finite.
        finite = (pos_next.sum(1) + quat_next.sum(1) + angvel[:, 0].sum(1)).isfinite()
        speed, far = vel[:, 0].norm(dim=1), pos_next.abs().amax(1)
        bad = ~finite | (speed > self.bound) | (far > max_pos)
        if not bool(bad.any()):
            return None
        per_scene = torch.zeros(self.num_graphs, dtype=torch.long, device=bad.device)
        return (per_scene.index_add_(0, self.node_batch, bad.to(torch.long)) > 0).tolist()


def start_state(frames: TrajectoryFrames, h: int) -> SceneState:
    s = frames.state(h, h)
    s.target_vel = s.target_angvel = None  # a simulator must not see the answer
    return s


class FrameRecord:
    """The frames of every scene of a batch, ``[T, N_total, ·]`` float32 per key, kept on the
    rollout's device: a frame is written there, and the frames reach the host once, when the
    rollout ends (no copy to the host per frame)."""

    def __init__(self, frames: list[TrajectoryFrames], t_max: int, h: int, device):
        counts = [f.pos.shape[1] for f in frames]
        self.offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        n, self.device = int(self.offsets[-1]), device
        self.arrays = {
            k: torch.zeros(t_max, n, w, dtype=torch.float32, device=device)
            for k, w in _RECORDED.items()
        }
        for f, lo, hi in zip(frames, self.offsets[:-1], self.offsets[1:], strict=True):
            for key, array in self.arrays.items():
                array[: h + 1, lo:hi] = getattr(f, key)[: h + 1].to(device)

    def nodes(self, active: list[int]) -> torch.Tensor:
        """Columns of the records of the active scenes' spheres, ``[N]`` on the device."""
        spans = [np.arange(self.offsets[i], self.offsets[i + 1]) for i in active]
        columns = np.concatenate(spans) if spans else np.zeros(0, dtype=np.int64)
        return torch.as_tensor(columns, device=self.device)

    def write(self, t: int, nodes: torch.Tensor, state: SceneBatch) -> None:
        self.arrays["pos"][t, nodes] = state.pos.float()
        self.arrays["quat"][t, nodes] = state.quat.float()
        self.arrays["vel"][t, nodes] = state.vel[:, 0].float()
        self.arrays["angvel"][t, nodes] = state.angvel[:, 0].float()

    def host(self) -> None:
        """Bring the records to the host as numpy arrays (once, at the end)."""
        self.arrays = {k: a.cpu().numpy() for k, a in self.arrays.items()}

    def frames_of(self, i: int, end: int) -> dict:
        lo, hi = self.offsets[i], self.offsets[i + 1]
        return {k: a[:end, lo:hi].copy() for k, a in self.arrays.items()}


def one_step(simulator, state: SceneBatch, max_pos: float, hold, timer: StepTimer | None):
    """Predict and integrate one frame of the batch (timed when a timer is given)."""
    if timer is None:
        return state.step(simulator(state.batch), max_pos, hold)
    with timer.watch(simulator):
        answer = timer.predict(simulator, state.batch)
    return timer.integrate(state.step, answer, max_pos, hold)
