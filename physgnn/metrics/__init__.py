"""Physics and accuracy metrics of one trajectory (pure functions; numpy in, floats out).

Arrays are converted to float64. Every function refuses NaN/inf input and empty scenes with
one :class:`MetricError` line instead of returning a silent NaN. Conventions:

- penetration: an *intersection* is a (sphere pair | sphere–plane, frame) with a positive
  depth; its normalised depth is the depth divided by the diameter (pairs: the mean diameter
  ``r_i + r_j``). ``depth_*`` is the mean normalised depth of all intersections (0 when there
  is none); ``pct_*`` the percentage of spheres with at least one intersection whose
  normalised depth exceeds ``tol`` (default 0: any overlap counts, as in the report).
  The ground (kind 0) is a half-space: depth ``r − (p − c)·n``. Other planes (walls, static)
  are one-sided bounded rectangles: depth ``r − |p − closest point of the rectangle|`` in
  front, ``r + |h|`` for a centre at height ``−r < h < 0`` behind the rectangle. A plane depth
  above ``r`` (normalised 0.5) means the centre crossed the plane: ``tunnelled`` counts
  those spheres.
- energy: kinetic + potential ``m·g·(z − r)`` (:mod:`physgnn.physics.energy`) from the velocities
  given (ground truth: the engine's by default; rollouts: their own); the normalised gain is
  ``Σ max(0, E_{k+1} − E_k) / E_0``; when ``E_0`` is zero (``≤ 1e-6·Σ m·g·r``, float noise of a
  resting scene) or negative, the sum is divided by ``Σ m·g·r`` instead.
- accuracy metrics are averaged over all frames given (seed frames included, as the report).
"""

from physgnn.metrics.checks import TOLERANCE, MetricError, check_tolerance
from physgnn.metrics.penetration import (
    PENETRATION_KEYS,
    max_penetration,
    penetration,
    plane_distance,
    sphere_overlaps,
)
from physgnn.metrics.series import (
    chamfer,
    drift_before_hit,
    energy_gain,
    energy_rise,
    energy_scale,
    energy_series,
    momentum_drift,
    mse_at,
    position_mse,
    rest_drift,
    resting_mask,
    rotation_error,
)
from physgnn.metrics.trajectory import trajectory_metrics

__all__ = [
    "PENETRATION_KEYS",
    "TOLERANCE",
    "MetricError",
    "chamfer",
    "check_tolerance",
    "drift_before_hit",
    "energy_gain",
    "energy_rise",
    "energy_scale",
    "energy_series",
    "max_penetration",
    "momentum_drift",
    "mse_at",
    "penetration",
    "plane_distance",
    "position_mse",
    "rest_drift",
    "resting_mask",
    "rotation_error",
    "sphere_overlaps",
    "trajectory_metrics",
]
