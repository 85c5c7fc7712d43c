"""Stability of simulators on hard scenes: the rows of ``stability.csv``.

Every learned run is rolled out (:func:`physgnn.rollout.rollout`) on the hard scenes
(:func:`physgnn.groundtruth.hard.hard_split`) and, through the eval, on its dataset's OOD
scenes. One row per (run, scene), columns :data:`physgnn.report.stability.COLUMNS`:

- ``diverged_at``: first non-finite / runaway frame (None: stable to the end);
  ``steps_to_divergence`` = ``diverged_at − start`` (steps the model took before it).
- ``max_pen_sphere``, ``max_pen_ground``, ``max_pen_static``: the deepest intersection of the
  rollout, ``mean_pen_sphere`` the mean sphere–sphere depth and ``tunnelled`` the spheres whose
  centre crossed a plane (:func:`physgnn.metrics.max_penetration`; planes are one-sided).
- ``energy_gain``: :func:`physgnn.metrics.energy_gain` of the rollout's energy (its own
  finite-difference velocities; the ground-truth row uses the engine's positions with
  finite-difference velocities too, so the rows compare like with like); ``energy_rise`` the
  largest climb above the initial energy (:func:`physgnn.metrics.energy_rise`).
- ``rest_drift``: largest displacement, in radii, of the spheres that rest in the ground truth
  (move less than ``rest_tol`` radii over the whole trajectory; ``n_resting`` of them); None
  when no sphere rests.

Metrics of a diverged rollout are computed on its finite prefix.
"""

from __future__ import annotations

from physgnn import metrics
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout


def measure(truth: Trajectory, pred: Trajectory, rest_tol: float = 0.01) -> dict:
    """The stability numbers of one rollout ``pred`` of ``truth``'s scene (the columns from
    ``scene`` on); ``pred`` holds the rollout's finite prefix."""
    vel = pred.with_finite_velocities().vel  # every simulator's energy alike (metrics_row)
    energy = metrics.energy_series(pred.pos, vel, truth.mass, truth.radius)
    resting = metrics.resting_mask(truth.pos, truth.radius, rest_tol)
    diverged_at, start = pred.diverged_at, int(pred.start)
    scale = metrics.energy_scale(truth.mass, truth.radius)
    return {
        "scene": truth.name,
        "n_spheres": truth.n_spheres,
        "n_frames": pred.n_frames,
        "start": start,
        "diverged_at": diverged_at,
        "steps_to_divergence": None if diverged_at is None else int(diverged_at) - start,
        **metrics.max_penetration(pred.pos, truth.radius, truth.planes, truth.plane_kind),
        "energy_gain": metrics.energy_gain(energy, scale),
        "energy_rise": metrics.energy_rise(energy, scale),
        "rest_drift": metrics.rest_drift(pred.pos, truth.radius, resting),
        "n_resting": int(resting.sum()),
    }


def truth_row(truth: Trajectory, source: str, rest_tol: float = 0.01) -> dict:
    """The ground truth's own row (engine positions, finite-difference velocities)."""
    row = measure(truth, truth, rest_tol=rest_tol)
    return {"run": "ground_truth", "experiment": "ground_truth", "source": source, **row}


def rollout_rows(
    name: str,
    experiment: str,
    simulator,
    trajectories: list[Trajectory],
    source: str,
    rest_tol: float = 0.01,
    **rollout_kwargs,
) -> list[dict]:
    """Roll ``simulator`` out on every trajectory (from its first H+1 frames; keyword
    arguments of :func:`physgnn.rollout.rollout`, e.g. ``sleep``) and measure."""
    rows = []
    for truth, pred in zip(
        trajectories, rollout(simulator, trajectories, **rollout_kwargs), strict=True
    ):
        row = measure(truth, pred, rest_tol)
        rows.append({"run": name, "experiment": experiment, "source": source, **row})
    return rows
