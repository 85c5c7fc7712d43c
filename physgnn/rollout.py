"""Autoregressive rollout of a simulator over many scenes at once, with divergence detection.

A simulator is any :class:`~physgnn.models.protocol.Simulator`: ``simulator(state) ->
(vel_next [N, 3], angvel_next [N, 3])`` on a batched :class:`~physgnn.data.state.SceneState`,
in physical units (the learned simulator and the baselines share this call). Each trajectory
starts from its first ``H + 1`` ground-truth frames (the state at frame ``H``); every step is
:func:`physgnn.physics.integrator.step` (semi-implicit Euler, then the velocity histories
shifted by the velocities the move implies, as the training features are computed).

A scene stops when a frame turns non-finite or runs away (a speed above the bound, a
coordinate beyond ``max_pos``: :class:`RolloutBounds`); ``diverged_at`` is the index of that
first bad frame and the scene's arrays keep only the frames before it. The other scenes of
the batch continue. Each result is a :class:`~physgnn.physics.trajectory.Trajectory`, the
container the truth uses.
The frames are recorded on the rollout's device and reach the host once, at the end.
"""

from __future__ import annotations

import copy
import dataclasses
import warnings

import numpy as np
import torch
from torch_geometric.data import Batch

from physgnn.data.state import SceneState, TrajectoryFrames, has_engine_velocities, layout_of
from physgnn.errors import PhysgnnError
from physgnn.models.profiling import StepTimer
from physgnn.models.protocol import hooks_of, motion_of
from physgnn.models.sleeping import SleepingSimulator
from physgnn.physics import integrator
from physgnn.physics.scene import EFFECT_NAMES
from physgnn.physics.trajectory import Trajectory

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


class RolloutError(PhysgnnError, ValueError):
    """A rollout cannot start (one line naming the problem)."""


@dataclasses.dataclass(frozen=True)
class RolloutBounds:
    """When a scene runs away: a sphere faster than ``max_speed`` m/s or, if ``speed_factor``
    is set, than ``speed_factor × max(largest true speed, min_speed)``; or a coordinate beyond
    ``max_pos`` m."""

    max_speed: float = 1e4
    speed_factor: float | None = None
    min_speed: float = 1.0
    max_pos: float = 1e6


def rollout(
    simulator,
    trajectories: list[Trajectory],
    history: int | None = None,
    n_frames: int | None = None,
    *,
    bounds: RolloutBounds | None = None,
    batch_size: int | None = None,
    device: str | torch.device | None = None,
    dtype: torch.dtype = torch.float32,
    sleep: bool | dict = False,
    timer: StepTimer | None = None,
) -> list[Trajectory]:
    """Roll every trajectory out from its first ``history + 1`` frames, without gradients.

    ``history`` defaults to the simulator's ``H``. ``n_frames``: frames per rollout, seed
    frames included (default: each trajectory's length; may exceed it). ``bounds``: when a
    scene runs away (:class:`RolloutBounds`; None: its defaults). ``batch_size`` scenes share
    one graph (None: all). ``sleep``: resting spheres are frozen
    (:class:`~physgnn.models.sleeping.SleepingSimulator`, one per batch): True with its
    default settings, a dict of its ``threshold``, ``k``, ``touch``; False: off. ``timer``
    (opt-in) splits the steps' seconds into graph, network and integration.
    """
    hooks = hooks_of(simulator)
    h = _history(hooks.history, history)
    lengths = [n_frames or t.n_frames for t in trajectories]
    for traj, length in zip(trajectories, lengths, strict=True):
        _check_start(traj, length, h)
    _warn_unseen_effects(hooks.effects_trained, trajectories)
    _warn_finite_differences(hooks.engine_state, trajectories)
    settings = dict(
        h=h,
        bounds=bounds if bounds is not None else RolloutBounds(),
        device=torch.device(device if device is not None else hooks.device),
        dtype=dtype,
        timer=timer,
    )
    size = batch_size or max(len(trajectories), 1)
    results = []
    with torch.inference_mode():
        for i in range(0, len(trajectories), size):
            sim = _sleeping(simulator, sleep)
            chunk = slice(i, i + size)
            results += _rollout_batch(sim, trajectories[chunk], lengths[chunk], **settings)
    return results


def _sleeping(simulator, sleep: bool | dict):
    """``simulator`` itself (``sleep`` False) or wrapped in a fresh SleepingSimulator."""
    if sleep is False:
        return simulator
    if sleep is True:
        return SleepingSimulator(simulator)
    if isinstance(sleep, dict):
        return SleepingSimulator(simulator, **sleep)
    raise RolloutError(
        f"sleep must be True, False or a dict of SleepingSimulator settings (got {sleep!r})"
    )


def _history(own: int | None, history: int | None) -> int:
    if history is None and own is None:
        raise RolloutError("pass history=H: the simulator has no integer 'H'")
    return int(history) if history is not None else own


def _check_start(traj: Trajectory, length: int, h: int) -> None:
    if traj.n_spheres == 0:
        raise RolloutError(f"trajectory '{traj.name}' has no sphere")
    if not np.isfinite(traj.pos[: h + 1]).all() or not np.isfinite(traj.quat[: h + 1]).all():
        raise RolloutError(f"trajectory '{traj.name}' has NaN or inf in its first {h + 1} frames")
    if traj.n_frames < h + 1 or length < h + 1:
        raise RolloutError(
            f"trajectory '{traj.name}' needs at least H+1 = {h + 1} frames to start "
            f"(has {traj.n_frames}, rollout of {length})"
        )


def _warn_unseen_effects(trained, trajectories: list[Trajectory]) -> None:
    """One warning line when a scene asks for an effect the model was not trained with
    (``trained [5]`` bool, order of ``EFFECT_NAMES``; None: no check)."""
    if trained is None:
        return
    asked = {name for t in trajectories for name in EFFECT_NAMES if getattr(t.effects, name)}
    unseen = [
        n for n, seen in zip(EFFECT_NAMES, trained.tolist(), strict=True) if n in asked and not seen
    ]
    if unseen:
        message = f"rollout asks for effect(s) {unseen} that the model never saw in training"
        warnings.warn(message, UserWarning, stacklevel=3)


def _warn_finite_differences(engine_state: bool, trajectories: list[Trajectory]) -> None:
    """One warning line when a model of the engine state starts from trajectories without an
    engine's velocities (positions only: their finite differences stand in)."""
    plain = [t.name for t in trajectories if not has_engine_velocities(t)]
    if engine_state and plain:
        message = (
            f"{len(plain)} trajectory(ies) ({plain[0]}, ...) hold no engine velocities: the "
            "engine-state model starts from their finite differences (docs/MODEL.md)"
        )
        warnings.warn(message, UserWarning, stacklevel=3)


def _speed_bound(frames: TrajectoryFrames, bounds: RolloutBounds) -> float:
    if bounds.speed_factor is None:
        return bounds.max_speed
    finite = torch.nan_to_num(frames.vel, nan=0.0, posinf=0.0, neginf=0.0)
    true_max = float(finite.norm(dim=-1).max()) if finite.numel() else 0.0
    return min(bounds.max_speed, bounds.speed_factor * max(true_max, bounds.min_speed))


class _Batch:
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


def _start_state(frames: TrajectoryFrames, h: int) -> SceneState:
    s = frames.state(h, h)
    s.target_vel = s.target_angvel = None  # a simulator must not see the answer
    return s


class _Record:
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

    def write(self, t: int, nodes: torch.Tensor, state: _Batch) -> None:
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


def _rollout_batch(simulator, trajs, lengths, *, h, bounds, device, dtype, timer):
    frames = [TrajectoryFrames(t, hooks_of(simulator).engine_state) for t in trajs]
    record = _Record(frames, max(lengths), h, device)
    speed_bound = torch.tensor([_speed_bound(f, bounds) for f in frames], dtype=torch.float64)
    state = _Batch([_start_state(f, h) for f in frames], speed_bound, device, dtype)
    diverged: list[int | None] = [None] * len(trajs)
    ends = list(lengths)
    hooks = hooks_of(simulator)
    steps, t = 0, h
    start_time = StepTimer.clock(device)
    if min(lengths) == h + 1:  # nothing to compute for these
        state.keep([k for k, i in enumerate(state.active) if lengths[i] > h + 1])
    nodes = record.nodes(state.active)
    while state.batch is not None and t + 1 < max(lengths):
        bad = _one_step(simulator, state, bounds.max_pos, hooks.hold, timer)
        t, steps = t + 1, steps + 1
        record.write(t, nodes, state)
        keep = []
        for k, i in enumerate(state.active):
            if bad is not None and bad[k]:
                diverged[i] = ends[i] = t
            elif t + 1 < lengths[i]:
                keep.append(k)
        if len(keep) < len(state.active):
            if hooks.select is not None:
                index = torch.tensor(keep, dtype=torch.long, device=state.node_batch.device)
                hooks.select(torch.isin(state.node_batch, index))
            state.keep(keep)
            nodes = record.nodes(state.active)
    total = StepTimer.clock(device) - start_time
    record.host()
    if timer is not None:
        timer.timings["total"] += total
    fps = steps / total if total > 0 else float("inf")
    return [
        dataclasses.replace(
            traj,
            **record.frames_of(i, ends[i]),
            attrs=dict(traj.attrs),
            start=h,
            diverged_at=diverged[i],
            fps=fps,
        )
        for i, traj in enumerate(trajs)
    ]


def _one_step(simulator, state: _Batch, max_pos: float, hold, timer: StepTimer | None):
    """Predict and integrate one frame of the batch (timed when a timer is given)."""
    if timer is None:
        return state.step(simulator(state.batch), max_pos, hold)
    with timer.watch(simulator):
        answer = timer.predict(simulator, state.batch)
    return timer.integrate(state.step, answer, max_pos, hold)
