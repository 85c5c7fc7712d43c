"""The one list of the metrics: each name with its unit, what it measures and where it is shown.

Every view reads its metrics from here: ``make eval``'s ``metrics.csv`` and the report's tables
(:data:`TABLE`), the same-work table and the Pareto figures (:data:`PARETO`, their axis labels
:func:`label`) and ``simulate``'s ``metrics.json`` (:func:`scene_columns`). A new measure is its
function, its key in :func:`~physgnn.metrics.trajectory_metrics` and its entry here; the full
definition of each is in docs/EVALUATION.md ("Metrics"), whose table is tested to name the same
metrics with the same units.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Metric:
    """One measure of a trajectory or a rollout.

    ``unit`` is "" for a ratio without unit. ``lower_is_better`` is None for a size or a frame
    index (not a score). ``of_prediction``: it measures a prediction (against the truth, or its
    divergence or speed) and means nothing for the truth alone. ``by_trajectory_metrics``: a key
    of :func:`~physgnn.metrics.trajectory_metrics` (else measured elsewhere, as its description
    says). ``in_table``: a column of ``metrics.csv``. ``pareto``: in the same-work table and a
    Pareto figure of its own.
    """

    name: str
    unit: str
    description: str
    lower_is_better: bool | None = True
    of_prediction: bool = False
    by_trajectory_metrics: bool = True
    in_table: bool = False
    pareto: bool = False


# In the order of metrics.csv's columns.
METRICS: tuple[Metric, ...] = (
    Metric("n_spheres", "spheres", "spheres in the scene", lower_is_better=None),
    Metric(
        "n_frames",
        "frames",
        "frames measured (of a diverged rollout: its finite prefix)",
        lower_is_better=None,
    ),
    Metric("mse", "m²", "position MSE over all frames", of_prediction=True, in_table=True),
    Metric(
        "mse20",
        "m²",
        "position MSE at frame H + 20",
        of_prediction=True,
        in_table=True,
        pareto=True,
    ),
    Metric(
        "chamfer",
        "m²",
        "Chamfer distance (squared, per frame)",
        of_prediction=True,
        in_table=True,
        pareto=True,
    ),
    Metric("energy_gain", "", "normalised cumulative energy gain", in_table=True, pareto=True),
    Metric(
        "depth_sphere",
        "diameters",
        "penetration: mean depth sphere–sphere",
        in_table=True,
        pareto=True,
    ),
    Metric(
        "depth_ground",
        "diameters",
        "penetration: mean depth sphere–ground",
        in_table=True,
        pareto=True,
    ),
    Metric(
        "depth_static", "diameters", "penetration: mean depth sphere–other plane", in_table=True
    ),
    Metric("pct_sphere", "%", "spheres intersecting another sphere", in_table=True),
    Metric("pct_ground", "%", "spheres intersecting the ground", in_table=True),
    Metric("pct_static", "%", "spheres intersecting another plane", in_table=True),
    Metric(
        "rotation_error",
        "rad",
        "mean angle between predicted and true orientations",
        of_prediction=True,
        in_table=True,
    ),
    Metric(
        "momentum_drift",
        "m/s",
        "largest change of the total momentum over the total mass (no external force)",
    ),
    Metric(
        "rest_drift",
        "radii",
        "largest displacement of the spheres that rest in the truth",
        of_prediction=True,
    ),
    Metric(
        "drift_before_hit",
        "radii",
        "largest drift of a resting sphere before the truth moves it",
        of_prediction=True,
        in_table=True,
    ),
    Metric(
        "diverged_at",
        "frame",
        "first non-finite or runaway frame of a rollout",
        lower_is_better=None,
        of_prediction=True,
        in_table=True,
    ),
    Metric(
        "fps",
        "frames/s",
        "rollout frames per second (the evaluation's clock)",
        lower_is_better=False,
        of_prediction=True,
        by_trajectory_metrics=False,
        in_table=True,
    ),
    Metric(
        "tunnelled",
        "spheres",
        "spheres whose centre crossed a plane (max_penetration, the stability table)",
        by_trajectory_metrics=False,
    ),
    Metric(
        "energy_rise",
        "",
        "largest rise of the energy above its start (the stability table)",
        by_trajectory_metrics=False,
    ),
)
BY_NAME = {metric.name: metric for metric in METRICS}
# metrics.csv's metric columns, in order (diverged_at and fps last)
TABLE = tuple(m.name for m in METRICS if m.in_table)
# The same-work table's columns and the Pareto figures: each against the cost (lower is better)
PARETO = tuple(m.name for m in METRICS if m.pareto)


def scene_columns(prediction: bool) -> tuple[str, ...]:
    """The metrics of one scene (``simulate``'s ``metrics.json``): the table's columns that
    :func:`~physgnn.metrics.trajectory_metrics` computes; without a ``prediction`` (the truth
    alone) only those that do not measure a prediction."""
    return tuple(
        m.name
        for m in METRICS
        if m.in_table and m.by_trajectory_metrics and (prediction or not m.of_prediction)
    )


def label(name: str) -> str:
    """``"description (unit)"`` of a registered metric (an axis label); else the name."""
    metric = BY_NAME.get(name)
    if metric is None:
        return name
    return f"{metric.description} ({metric.unit})" if metric.unit else metric.description
