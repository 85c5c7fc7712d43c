"""The one-step error by regime: ``onestep.csv`` of ``make eval``.

From every true state at ``t`` (``t ≥ H`` to the last but one frame; with ``frames`` set, that
many frames per trajectory, evenly spaced), each simulator predicts the position at ``t + 1``;
the squared error ``‖p̂_{t+1} − p_{t+1}‖²`` of every sphere-frame is split by the regime the
truth shows in that frame (:mod:`physgnn.metrics.regimes`, the same labels for every
simulator). Rows: per learned run and per pybullet substep count, per split, one row per
regime and ``all``: its sphere-frames, their share, the mean squared error (m²) and the
regime's share of the summed squared error.

- A learned run: the state at ``t`` is ``TrajectoryFrames(traj, engine_state).state(t, H)``
  (the run's own history and state: finite-difference or engine velocities), many frames of a
  trajectory in one batch, without gradients; the answer moves the spheres as a rollout's
  frame does (:func:`physgnn.physics.integrator.step`: the mean motion of an engine-state
  answer, else the velocities).
- ``pybullet-<k>``: the engine at ``k`` substeps and the truth's other settings
  (:func:`physgnn.evaluation.same_work.engine_of`), restarted from the truth's positions,
  orientations and stored engine velocities at ``t`` and stepped one frame
  (:func:`physgnn.groundtruth.engine.one_frame_from`: the bodies of a trajectory made once,
  each start set by reset), on the frames of each history ``H`` of the learned runs.
"""

from __future__ import annotations

from functools import partial

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from torch_geometric.data import Batch

from physgnn.data.state import TrajectoryFrames, layout_of
from physgnn.errors import ConfigError
from physgnn.evaluation.rollouts import progress
from physgnn.evaluation.runs import SPLITS, RunInfo
from physgnn.evaluation.same_work import engine_jobs, engine_name, engine_of
from physgnn.groundtruth.engine import one_frame_from
from physgnn.metrics.regimes import regime_labels, regime_rows, tally
from physgnn.models.protocol import hooks_of, motion_of
from physgnn.physics import integrator
from physgnn.physics.scene import EFFECT_NAMES, GRAVITY
from physgnn.physics.trajectory import Trajectory, scene_at
from physgnn.ranges import whole

ROTATION = EFFECT_NAMES.index("rotation")
NODES = 4096  # spheres per batch of frames of one trajectory


def check_settings(cfg: DictConfig | None) -> tuple[list[str], int | None] | None:
    """``(splits, frames)`` of the eval's ``onestep`` config (None: no table)."""
    if cfg is None:
        return None
    splits = OmegaConf.to_container(cfg.splits) if cfg.get("splits") is not None else None
    if not isinstance(splits, list) or not splits or not set(splits) <= set(SPLITS):
        raise ConfigError(f"onestep.splits must be a list of {list(SPLITS)}, got {splits!r}")
    frames = whole(1, also=(None,), what="null: every frame").check(
        "onestep.frames", cfg.get("frames")
    )
    return list(dict.fromkeys(splits)), frames


def onestep_frames(traj: Trajectory, H: int, frames: int | None = None) -> np.ndarray:
    """The frames ``t`` predicted from: ``H .. T − 2``, or ``frames`` of them evenly spaced."""
    ts = np.arange(H, traj.n_frames - 1)
    if frames is None or len(ts) <= frames:
        return ts
    return np.unique(np.linspace(H, traj.n_frames - 2, frames).round().astype(np.int64))


def truth_labels(traj: Trajectory) -> np.ndarray:
    """``[T − 1, N]`` regimes of the truth's frames (:func:`regime_labels`)."""
    gravity = traj.attrs.get("gravity", GRAVITY) if traj.effects.gravity else (0.0, 0.0, 0.0)
    return regime_labels(
        traj.pos, traj.vel, traj.radius, traj.planes, traj.plane_kind, traj.dt, gravity
    )


@torch.inference_mode()
def learned_positions(sim, traj: Trajectory, ts: np.ndarray) -> np.ndarray:
    """``[len(ts), N, 3]``: the simulator's positions at ``t + 1`` from the true states at
    ``ts``, as a rollout's frame moves them (float64)."""
    hooks = hooks_of(sim)
    frames = TrajectoryFrames(traj, hooks.engine_state)
    chunk = max(1, NODES // traj.n_spheres)
    out = []
    for lo in range(0, len(ts), chunk):
        states = [_bare(frames.state(int(t), hooks.history)) for t in ts[lo : lo + chunk]]
        batch = Batch.from_data_list(states)
        batch.host_sizes = layout_of(states)
        b = batch.to(hooks.device)
        (vel, angvel), mean = motion_of(sim(b))
        rotate = b.effects[b.batch, ROTATION]
        pos, *_ = integrator.step(
            b.pos, b.quat, b.vel, b.angvel, vel, angvel, b.dt[b.batch], rotate, hooks.hold, mean
        )
        out.append(pos.double().cpu().numpy().reshape(len(states), traj.n_spheres, 3))
    return np.concatenate(out) if out else np.zeros((0, traj.n_spheres, 3))


def _bare(state):
    """A state without its answers (a simulator must not see them)."""
    for key in ("target_vel", "target_angvel", "target_mean_vel", "target_mean_angvel"):
        state[key] = None
    return state


def engine_positions(traj: Trajectory, ts: np.ndarray, substeps: int) -> np.ndarray:
    """``[len(ts), N, 3]``: pybullet at ``substeps`` one frame on from the truth's states at
    ``ts`` (positions, orientations, stored engine velocities)."""
    starts = ((traj.pos[t], traj.quat[t], traj.vel[t], traj.angvel[t]) for t in ts)
    return one_frame_from(scene_at(traj, 0), starts, engine_of(traj, substeps))


def table_rows(name: str, split: str, truth: list[tuple], H: int, frames, predict) -> list[dict]:
    """The rows of one simulator on one split: ``truth`` is ``[(trajectory, labels), ...]``,
    ``predict(traj, ts)`` its positions at ``t + 1`` from the frames ``ts``."""
    counts, sums = tally(np.zeros((0,), np.int64), np.zeros((0,)))
    for traj, labels in truth:
        ts = onestep_frames(traj, H, frames)
        if len(ts) == 0:
            continue
        pred = predict(traj, ts)
        err = ((pred - np.asarray(traj.pos, np.float64)[ts + 1]) ** 2).sum(-1)
        c, s = tally(labels[ts], err)
        counts, sums = counts + c, sums + s
    return [{"run": name, "split": split} | row for row in regime_rows(counts, sums)]


def onestep_rows(
    runs: list[RunInfo], data: dict, settings: tuple, substeps: list[int], several: bool
) -> list[dict]:
    """The table of every learned run and of pybullet at each of ``substeps`` on the
    ``settings = (splits, frames)`` of their datasets (``several``: more than one dataset,
    the pybullet rows named by theirs, as :func:`~physgnn.evaluation.same_work.engine_jobs`)."""
    splits, frames = settings
    learned = [r for r in runs if r.simulator is not None and r.run_dir is not None]
    jobs = [
        (r.name, r.dataset, int(r.simulator.H), partial(learned_positions, r.simulator))
        for r in learned
    ] + [
        (
            engine_name(k, job),
            job.dataset,
            job.extra["H"],
            partial(engine_positions, substeps=k),
        )
        for job in engine_jobs(learned, several)
        for k in substeps
    ]
    truth = {
        (d, s): [(t, truth_labels(t)) for t in data[d].get(s, [])]
        for d in {r.dataset for r in learned}
        for s in splits
    }
    rows = []
    with progress() as bar:
        task = bar.add_task("one step", total=len(jobs) * len(splits))
        for split in splits:
            for name, dataset, H, predict in jobs:
                bar.update(task, description=f"one step · {name} · {split}")
                rows += table_rows(name, split, truth[dataset, split], H, frames, predict)
                bar.advance(task)
    return rows
