"""What the study measures of one trained run: every test and OOD trajectory rolled out to one
common horizon, each measured alike for the truth and the rollout.

- **Common horizon.** Every rollout runs to frame ``horizon`` of its trajectory (the truth cut
  there too). A rollout that diverges before it has *no* accuracy or physics figures: its
  ``diverged_at`` step is the result, never the average of the prefix it managed (a model
  diverging at step 12 would otherwise score the low error of 12 easy frames).
- **One energy measure.** Truth and rollout both get finite-difference velocities
  (:meth:`~physgnn.physics.trajectory.Trajectory.with_finite_velocities`, whatever the
  model's own velocities are):
  ``energy_gain_truth`` is what a perfect model would score, the floor of ``energy_gain``.
- **Divergence.** A sphere faster than ``speed_factor`` × the truth's fastest (at least
  1 m/s), or a non-finite frame (:func:`physgnn.rollout.rollout`).
- Plane penetration is one-sided (:mod:`physgnn.metrics.penetration`): a sphere that went
  through a wall counts as deep as it went; ``max_depth_sphere`` / ``max_depth_plane`` are the
  deepest intersection of the rollout over the diameter and ``tunnelled`` the spheres whose
  centre crossed a plane. ``energy_error`` is ``|energy_gain − energy_gain_truth|``: the truth's
  gain is the target, not a floor (a model that never moves scores 0 gain).
- With ``constraints`` > 0 the learned step is followed by the constraint stage
  (:class:`~physgnn.models.constrained.ConstrainedSimulator`, that many iterations).
"""

from __future__ import annotations

from pathlib import Path

from physgnn import metrics
from physgnn.evaluation.runs import dataset_of, load_splits
from physgnn.metrics import max_penetration
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import RolloutBounds, rollout
from physgnn.training.runs import load_run

SPLITS = ("test", "ood")
FIGURES = (
    "mse",
    "chamfer",
    "energy_gain",
    "energy_error",
    "depth_sphere",
    "depth_ground",
    "depth_static",
    "pct_sphere",
    "max_depth_sphere",
    "max_depth_plane",
    "tunnelled",
)


def measure_trajectory(simulator, traj: Trajectory, speed_factor: float) -> dict:
    """One record: the rollout's figures (None after a divergence), the truth's energy gain,
    ``diverged_at`` (frames after the seed frames, None when it reached the horizon), FPS."""
    pred = rollout(simulator, [traj], bounds=RolloutBounds(speed_factor=speed_factor))[0]
    truth = metrics.trajectory_metrics(traj.with_finite_velocities(), traj)
    record = {
        "trajectory": traj.name,
        "n_spheres": int(traj.n_spheres),
        "frames": int(traj.n_frames),
        "diverged_at": None,
        "energy_gain_truth": truth["energy_gain"],
        "fps": float(pred.fps) if pred.fps is not None else None,
    }
    if pred.diverged_at is not None:
        record["diverged_at"] = int(pred.diverged_at) - int(pred.start)
        return record | dict.fromkeys(FIGURES)
    m = metrics.trajectory_metrics(pred.with_finite_velocities(), traj)
    deepest = max_penetration(pred.pos, traj.radius, traj.planes, traj.plane_kind)
    m |= {
        "energy_error": abs(m["energy_gain"] - truth["energy_gain"]),
        "max_depth_sphere": deepest["max_pen_sphere"],
        "max_depth_plane": max(deepest["max_pen_ground"], deepest["max_pen_static"]),
        "tunnelled": deepest["tunnelled"],
    }
    return record | {k: m[k] for k in FIGURES}


def measure_run(
    run_dir: str | Path, horizon: int, speed_factor: float, constraints: int = 0
) -> dict[str, list]:
    """``{split: [record per trajectory]}`` of the run's test and OOD trajectories, each cut to
    ``horizon`` frames (:func:`measure_trajectory`)."""
    simulator, cfg, _ = load_run(run_dir)
    if constraints > 0:
        simulator = ConstrainedSimulator(simulator, constraints)
    splits = load_splits(dataset_of(cfg), horizon)
    return {
        split: [measure_trajectory(simulator, t, speed_factor) for t in splits.get(split, [])]
        for split in SPLITS
    }
