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
container the truth uses; its ``vel`` is the simulator's own (finite differences for a
finite-difference state, the predicted end-of-frame velocities for the engine state), and its
attribute ``velocity`` says which (:data:`VELOCITY`).
The frames are recorded on the rollout's device and reach the host once, at the end.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import torch

from physgnn.data.state import TrajectoryFrames, has_engine_velocities
from physgnn.errors import PhysgnnError
from physgnn.models.profiling import StepTimer
from physgnn.models.protocol import hooks_of
from physgnn.models.sleeping import SleepingSimulator
from physgnn.physics.scene import EFFECT_NAMES
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout.batch import FrameRecord, SceneBatch, one_step, start_state

# A rollout's attribute ``velocity``: what its ``vel`` holds, by the simulator's state
VELOCITY = {
    False: "finite differences of the predicted positions",
    True: "the model's predicted end-of-frame velocities (the engine state)",
}


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


def _rollout_batch(simulator, trajs, lengths, *, h, bounds, device, dtype, timer):
    frames = [TrajectoryFrames(t, hooks_of(simulator).engine_state) for t in trajs]
    record = FrameRecord(frames, max(lengths), h, device)
    speed_bound = torch.tensor([_speed_bound(f, bounds) for f in frames], dtype=torch.float64)
    state = SceneBatch([start_state(f, h) for f in frames], speed_bound, device, dtype)
    diverged: list[int | None] = [None] * len(trajs)
    ends = list(lengths)
    hooks = hooks_of(simulator)
    steps, t = 0, h
    start_time = StepTimer.clock(device)
    if min(lengths) == h + 1:  # nothing to compute for these
        state.keep([k for k, i in enumerate(state.active) if lengths[i] > h + 1])
    nodes = record.nodes(state.active)
    while state.batch is not None and t + 1 < max(lengths):
        bad = one_step(simulator, state, bounds.max_pos, hooks.hold, timer)
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
            attrs=dict(traj.attrs) | {"velocity": VELOCITY[hooks.engine_state]},
            start=h,
            diverged_at=diverged[i],
            fps=fps,
        )
        for i, traj in enumerate(trajs)
    ]
