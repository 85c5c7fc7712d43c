"""Autoregressive rollout of a simulator over many scenes at once, with divergence detection.

A *simulator* is any callable ``simulator(state) -> (vel_next [N, 3], angvel_next [N, 3])``
taking a batched :class:`physgnn.data.state.SceneState` and returning ``v_{t+1}``, ``ω_{t+1}`` in
physical units (the learned simulator and the baselines share this call). Each trajectory
starts from its first ``H + 1`` ground-truth frames (the state at frame ``H``), then every
step integrates the prediction with semi-implicit Euler and shifts the velocity histories
with the velocities the integrator implies, ``(p_{t+1} − p_t)/dt`` and
``log(q_{t+1} ⊗ q_t⁻¹)/dt``, exactly as the training features are computed.

A scene stops when a frame turns non-finite or runs away (a speed above the bound, a
coordinate beyond ``max_pos``); ``diverged_at`` is the index of that first bad frame and the
scene's arrays keep only the frames before it. The other scenes of the batch continue.
"""

from __future__ import annotations

import copy
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import torch
from torch_geometric.data import Batch

from physgnn.data.state import SceneState, TrajectoryFrames
from physgnn.errors import PhysgnnError
from physgnn.physics import quaternion as Q
from physgnn.physics.integrator import euler_step
from physgnn.physics.scene import EFFECT_NAMES, Trajectory

ROTATION = EFFECT_NAMES.index("rotation")
_FLOAT_KEYS = ("pos", "quat", "vel", "angvel", "radius", "mass", "planes", "dt")


class RolloutError(PhysgnnError, ValueError):
    """A rollout cannot start (one line naming the problem)."""


@dataclass
class RolloutResult:
    """One trajectory's rollout; frame ``k`` of the arrays is frame ``k`` of the trajectory.

    pos ``[T, N, 3]``, quat ``[T, N, 4]``, vel ``[T, N, 3]`` (finite differences; frames
    ``0..start`` are the ground truth's), float32. ``T = n_frames`` is the finite prefix when
    the rollout diverged (``diverged_at = T``, the first bad frame). ``fps`` = frames computed
    per second of wall time of the batch the scene ran in; ``timings`` (seconds, batch
    totals): ``graph``, ``network``, ``integration``, ``total`` and the count of ``steps``.
    """

    name: str
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    diverged_at: int | None
    n_frames: int
    fps: float
    timings: dict = field(default_factory=dict)
    start: int = 0

    def as_dict(self) -> dict:
        """The ``pred`` argument of :func:`physgnn.metrics.trajectory_metrics`."""
        return dict(pos=self.pos, quat=self.quat, vel=self.vel, start=self.start,
                    diverged_at=self.diverged_at)  # fmt: skip


def rollout(
    simulator,
    trajectories: list[Trajectory],
    history: int | None = None,
    n_frames: int | None = None,
    *,
    max_speed: float = 1e4,
    speed_factor: float | None = None,
    min_speed: float = 1.0,
    max_pos: float = 1e6,
    batch_size: int | None = None,
    device: str | torch.device | None = None,
    dtype: torch.dtype = torch.float32,
    sleeping: bool = False,
    sleep: dict | None = None,
) -> list[RolloutResult]:
    """Roll every trajectory out from its first ``history + 1`` frames, without gradients.

    ``history`` defaults to the simulator's ``H`` (or ``history``) attribute. ``n_frames``:
    frames per rollout, seed frames included (default: each trajectory's length; may exceed
    it). A scene runs away when a sphere is faster than ``max_speed`` m/s or, if
    ``speed_factor`` is set, than ``speed_factor × max(largest true speed, min_speed)``, or a
    coordinate exceeds ``max_pos`` m. ``batch_size`` scenes share one graph (None: all).
    ``sleeping``: resting spheres are frozen (:class:`physgnn.models.sleeping.SleepingSimulator`,
    built with the ``sleep`` kwargs ``threshold``, ``k``, ``touch``; one per batch).
    """
    h = _history(simulator, history)
    lengths = [n_frames or t.n_frames for t in trajectories]
    for traj, length in zip(trajectories, lengths, strict=True):
        if traj.n_spheres == 0:
            raise RolloutError(f"trajectory '{traj.name}' has no sphere")
        if not np.isfinite(traj.pos[: h + 1]).all() or not np.isfinite(traj.quat[: h + 1]).all():
            raise RolloutError(
                f"trajectory '{traj.name}' has NaN or inf in its first {h + 1} frames"
            )
        if traj.n_frames < h + 1 or length < h + 1:
            raise RolloutError(
                f"trajectory '{traj.name}' needs at least H+1 = {h + 1} frames to start "
                f"(has {traj.n_frames}, rollout of {length})"
            )
    _warn_unseen_effects(simulator, trajectories)
    if device is None:
        device = next((p.device for p in _parameters(simulator)), torch.device("cpu"))
    bounds = dict(max_speed=max_speed, speed_factor=speed_factor, min_speed=min_speed)
    size = batch_size or max(len(trajectories), 1)
    results = []
    with torch.inference_mode():
        for i in range(0, len(trajectories), size):
            chunk = list(range(i, min(i + size, len(trajectories))))
            sim = _sleeping(simulator, sleep) if sleeping else simulator
            results += _rollout_batch(
                sim, [trajectories[j] for j in chunk], [lengths[j] for j in chunk],
                h, bounds, max_pos, torch.device(device), dtype,
            )  # fmt: skip
    return results


def _history(simulator, history: int | None) -> int:
    if history is not None:
        return int(history)
    for name in ("H", "history"):
        if isinstance(getattr(simulator, name, None), int):
            return int(getattr(simulator, name))
    raise RolloutError("pass history=H: the simulator has no integer 'H' or 'history'")


def _warn_unseen_effects(simulator, trajectories: list[Trajectory]) -> None:
    """One warning line when a scene asks for an effect the model was not trained with
    (``simulator.effects_trained [5]`` bool, order of ``EFFECT_NAMES``; none: no check)."""
    trained = getattr(simulator, "effects_trained", None)
    if trained is None:
        return
    asked = {name for t in trajectories for name in EFFECT_NAMES if getattr(t.effects, name)}
    unseen = [
        n for n, seen in zip(EFFECT_NAMES, trained.tolist(), strict=True) if n in asked and not seen
    ]
    if unseen:
        warnings.warn(
            f"rollout asks for effect(s) {unseen} that the model never saw in training",
            UserWarning,
            stacklevel=3,
        )


def _sleeping(simulator, sleep: dict | None):
    from physgnn.models.sleeping import SleepingSimulator

    return SleepingSimulator(simulator, **(sleep or {}))


def _select(simulator, b: Batch, keep: list[int]) -> None:
    """Tell a simulator with per-sphere state (sleeping) which spheres of batch ``b`` stay."""
    select = getattr(simulator, "select", None)
    if select is not None:
        select(torch.isin(b.batch, torch.tensor(keep, dtype=torch.long, device=b.batch.device)))


def _parameters(simulator):
    """The simulator's parameters (also through a wrapper that delegates ``parameters``)."""
    parameters = getattr(simulator, "parameters", None)
    return parameters() if callable(parameters) else iter(())


def _speed_bound(frames: TrajectoryFrames, bounds: dict) -> float:
    if bounds["speed_factor"] is None:
        return bounds["max_speed"]
    finite = torch.nan_to_num(frames.vel, nan=0.0, posinf=0.0, neginf=0.0)
    true_max = float(finite.norm(dim=-1).max()) if finite.numel() else 0.0
    return min(bounds["max_speed"], bounds["speed_factor"] * max(true_max, bounds["min_speed"]))


def _clock(device: torch.device) -> float:
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()


def _graph_seconds(simulator) -> float:
    """The simulator's cumulative graph-building time (``timings['graph']``), 0 without."""
    timings = getattr(simulator, "timings", None)
    return float(timings.get("graph", 0.0)) if isinstance(timings, dict) else 0.0


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
        b = Batch.from_data_list(states).to(self.device)
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

    def step(self, vel_next, angvel_next, max_pos: float, hold=None) -> list[bool] | None:
        """Integrate one frame in place (positions, orientations, velocity histories).

        ``hold(pos, quat, pos_next, quat_next)`` (sleeping) may keep spheres in place.
        Returns None when every scene is fine, else a per-scene list: diverged?
        """
        pos, quat, dt = self.pos, self.quat, self.dt
        pos_next, quat_next = euler_step(pos, quat, vel_next, angvel_next, dt, self.rotate)
        if hold is not None:
            pos_next, quat_next = hold(pos, quat, pos_next, quat_next)
        vel_new = (pos_next - pos) / dt[:, None]
        if self.rotate is False and hold is None:
            angvel_new = torch.zeros_like(vel_new)  # orientation untouched
        else:
            angvel_new = Q.angular_velocity(quat, quat_next, dt[:, None])
        self.vel[:, 1:] = self.vel[:, :-1].clone()
        self.vel[:, 0] = vel_new
        self.angvel[:, 1:] = self.angvel[:, :-1].clone()
        self.angvel[:, 0] = angvel_new
        pos.copy_(pos_next)
        quat.copy_(quat_next)
        # One reduction: a NaN or inf anywhere in a row makes its sum non-finite.
        finite = (pos_next.sum(1) + quat_next.sum(1) + angvel_new.sum(1)).isfinite()
        bad = ~finite | (vel_new.norm(dim=1) > self.bound) | (pos_next.abs().amax(1) > max_pos)
        if not bool(bad.any()):
            return None
        per_scene = torch.zeros(self.num_graphs, dtype=torch.long, device=bad.device)
        return (per_scene.index_add_(0, self.node_batch, bad.to(torch.long)) > 0).tolist()


def _start_state(frames: TrajectoryFrames, h: int) -> SceneState:
    s = frames.state(h, h)
    for key in ("target_vel", "target_angvel"):  # a simulator must not see the answer
        if key in s:
            del s[key]
    return s


def _rollout_batch(simulator, trajs, lengths, h, bounds, max_pos, device, dtype):
    frames = [TrajectoryFrames(t) for t in trajs]
    counts = [t.n_spheres for t in trajs]
    offsets = np.concatenate([[0], np.cumsum(counts)])
    t_max = max(lengths)
    rec = {
        "pos": np.zeros((t_max, offsets[-1], 3), np.float32),
        "quat": np.zeros((t_max, offsets[-1], 4), np.float32),
        "vel": np.zeros((t_max, offsets[-1], 3), np.float32),
    }
    for f, lo, hi in zip(frames, offsets[:-1], offsets[1:], strict=True):
        for key in rec:
            rec[key][: h + 1, lo:hi] = getattr(f, key)[: h + 1].numpy()
    speed_bound = torch.tensor([_speed_bound(f, bounds) for f in frames], dtype=torch.float64)
    state = _Batch([_start_state(f, h) for f in frames], speed_bound, device, dtype)
    diverged: list[int | None] = [None] * len(trajs)
    ends = list(lengths)
    clock = {"graph": 0.0, "network": 0.0, "integration": 0.0}
    hold = getattr(simulator, "hold", None)
    steps, t = 0, h
    start_time = _clock(device)
    if min(lengths) == h + 1:  # nothing to compute for these
        state.keep([k for k, i in enumerate(state.active) if lengths[i] > h + 1])
    nodes = _nodes(offsets, state.active)  # columns of the records of the active spheres
    while state.batch is not None and t + 1 < t_max:
        t0, g0 = _clock(device), _graph_seconds(simulator)
        vel_next, angvel_next = simulator(state.batch)
        t1, g1 = _clock(device), _graph_seconds(simulator)
        bad = state.step(vel_next, angvel_next, max_pos, hold)
        t2 = _clock(device)
        clock["graph"] += g1 - g0
        clock["network"] += (t1 - t0) - (g1 - g0)
        clock["integration"] += t2 - t1
        t, steps = t + 1, steps + 1
        rec["pos"][t, nodes] = state.pos.float().cpu().numpy()
        rec["quat"][t, nodes] = state.quat.float().cpu().numpy()
        rec["vel"][t, nodes] = state.vel[:, 0].float().cpu().numpy()
        keep = []
        for k, i in enumerate(state.active):
            if bad is not None and bad[k]:
                diverged[i] = ends[i] = t
            elif t + 1 < lengths[i]:
                keep.append(k)
        if len(keep) < len(state.active):
            _select(simulator, state.batch, keep)
            state.keep(keep)
            nodes = _nodes(offsets, state.active)
    total = _clock(device) - start_time
    timings = dict(clock, total=total, steps=steps)
    fps = steps / total if total > 0 else float("inf")
    return [
        RolloutResult(
            name=traj.name,
            pos=rec["pos"][: ends[i], offsets[i] : offsets[i + 1]].copy(),
            quat=rec["quat"][: ends[i], offsets[i] : offsets[i + 1]].copy(),
            vel=rec["vel"][: ends[i], offsets[i] : offsets[i + 1]].copy(),
            diverged_at=diverged[i],
            n_frames=int(ends[i]),
            fps=fps,
            timings=dict(timings),
            start=h,
        )
        for i, traj in enumerate(trajs)
    ]


def _nodes(offsets: np.ndarray, active: list[int]) -> np.ndarray:
    if not active:
        return np.zeros(0, dtype=np.int64)
    return np.concatenate([np.arange(offsets[i], offsets[i + 1]) for i in active])
