"""Checked metric inputs: float64 arrays of the right shape, finite, one error line if not."""

from __future__ import annotations

import numpy as np

from physgnn.errors import PhysgnnError
from physgnn.ranges import number

# Above this many pair distances (T·N·M) the per-frame k-d tree paths are used.
BRUTE_FORCE_MAX = 2_000_000


# The penetration tolerance, a fraction of the diameter (make eval, simulate, api.score)
TOLERANCE = number(0, what="a fraction of the diameter; 0: any overlap counts", example=0)


class MetricError(PhysgnnError, ValueError):
    """A metric cannot be computed from its input (one line naming the problem)."""


def check_tolerance(tol, error: type = MetricError) -> float:
    """The penetration tolerance ``tol``: a finite number >= 0, a fraction of the diameter
    (``make eval``, ``simulate`` and ``api.score`` alike); else one line naming ``tol``."""
    return float(TOLERANCE.check("tol", tol, error=error))


def frames(x, name: str, width: int = 3) -> np.ndarray:
    """Checked ``[T, N, width]`` float64 array: at least one frame and one sphere, finite."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 3 or x.shape[-1] != width:
        raise MetricError(f"{name} must have shape [T, N, {width}], got {list(x.shape)}")
    if x.shape[0] == 0 or x.shape[1] == 0:
        raise MetricError(
            f"{name} is empty (shape {list(x.shape)}): no frame or no sphere; "
            f"need {name} [T, N, {width}] with T, N >= 1"
        )
    finite = np.isfinite(x).all(axis=(1, 2))
    if not finite.all():
        raise MetricError(f"{name} has NaN or inf at frame {int(np.argmin(finite))}")
    return x


def per_sphere(x, n: int, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (n,):
        raise MetricError(f"{name} must have shape [{n}], got {list(x.shape)}")
    if not np.isfinite(x).all():
        raise MetricError(f"{name} has NaN or inf")
    return x


def same_shape(a: np.ndarray, b: np.ndarray) -> None:
    if a.shape != b.shape:
        raise MetricError(f"prediction {list(a.shape)} and truth {list(b.shape)} differ in shape")
