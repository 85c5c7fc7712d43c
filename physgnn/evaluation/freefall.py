"""Free fall against the analytic answer: one sphere released at rest at several heights.

The learned simulator never sees absolute height (surface distances are clipped at the graph's
reach), so its free fall must be the same at 10, 100 and 1 000 m, and match
``z(t) = h − ½ g t²``. Each row: the rollout from the analytic seed frames (frames ``0..H``)
for ``seconds``, or less where the sphere would come within ``floor`` m of the ground (the fall
stays free); ``z_error`` = ``|ẑ(T) − z(T)|`` in m, ``z_error_pct`` the same as a percentage of
the fall ``½ g T²``, and ``dvz_first`` the velocity change of the first predicted step, from
positions (free flight: ``−g·dt``). Rows of ``freefall.csv`` and the report's free-fall section.
"""

from __future__ import annotations

import math

import numpy as np

from physgnn.physics.energy import G
from physgnn.physics.scene import Effects, ground_plane
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout

DENSITY = 1000.0  # kg/m³, that of the training scenes


ANALYTIC = "analytic"  # the truth's engine attribute: exact positions and velocities


def ballistic(
    name, pos0, vel0, radius, mass, material, frames: int, dt: float, fall: bool = True
) -> Trajectory:
    """Spheres flying freely from ``pos0 [N, 3]`` with ``vel0 [N, 3]``: exact positions and
    velocities of frames ``0..frames−1`` over the ground alone, one ``material`` row [4];
    ``fall=False``: uniform motion (spheres the ground holds: at rest, or sliding on it). Its
    velocities are the instantaneous ones at each frame (``engine`` attribute
    :data:`ANALYTIC`), what an engine-state model starts from."""
    t = np.arange(frames)[:, None, None] * dt
    drop = np.array([0.0, 0.0, -0.5 * G if fall else 0.0])
    pos = pos0[None] + vel0[None] * t + drop * t**2
    vel = vel0[None] + 2 * drop * t
    n = len(pos0)
    quat = np.zeros((frames, n, 4))
    quat[..., 0] = 1.0
    return Trajectory(
        name=name,
        pos=pos,
        quat=quat,
        vel=vel,
        angvel=np.zeros((frames, n, 3)),
        radius=np.asarray(radius, np.float64),
        mass=np.asarray(mass, np.float64),
        material=np.zeros(n, np.int64),
        planes=ground_plane()[None].astype(np.float64),
        plane_kind=np.zeros(1, np.int64),
        materials=np.asarray(material, np.float64)[None],
        dt=dt,
        effects=Effects(),
        attrs={"engine": ANALYTIC},
    )


def sphere_mass(radius, density: float = DENSITY) -> np.ndarray:
    """Masses (kg) of spheres of ``radius`` (m) and ``density`` (kg/m³)."""
    return density * 4.0 / 3.0 * np.pi * np.asarray(radius, np.float64) ** 3


def free_fall(height: float, seconds: float, dt: float, radius: float = 0.5) -> Trajectory:
    """One sphere of ``radius`` (density 1 000) released at rest at ``height`` m above the
    ground, frames ``k·dt`` for ``k = 0..seconds/dt``, exact positions and velocities."""
    radii = np.full(1, radius)
    return ballistic(
        f"free_fall_{height:g}m",
        np.array([[0.0, 0.0, height]]),
        np.zeros((1, 3)),
        radii,
        sphere_mass(radii),
        (0.5, 0.7, 0.01, 0.01),
        int(round(seconds / dt)) + 1,
        dt,
    )


def free_seconds(height: float, seconds: float, dt: float, floor: float) -> float:
    """``seconds``, cut to whole frames before the sphere falls below ``floor`` m."""
    frames = math.floor(math.sqrt(2.0 * max(height - floor, 0.0) / G) / dt + 1e-9)
    return min(seconds, frames * dt)


def freefall_rows(
    name: str, simulator, heights, seconds: float, dt: float, floor: float = 5.0, **kwargs
) -> list[dict]:
    """Roll ``simulator`` out from the analytic seed frames at each height (keyword arguments
    of :func:`physgnn.rollout.rollout`) and measure the rows
    (:data:`physgnn.report.freefall.COLUMNS`)."""
    truths = [free_fall(float(h), free_seconds(h, seconds, dt, floor), dt) for h in heights]
    rows = []
    for truth, pred in zip(truths, rollout(simulator, truths, **kwargs), strict=True):
        h, start = float(truth.pos[0, 0, 2]), int(pred.start)
        z_true = float(truth.pos[-1, 0, 2])
        stable = pred.diverged_at is None
        z_pred = float(pred.pos[-1, 0, 2]) if stable else float("nan")
        fall = float(h - z_true)
        rows.append(
            {
                "run": name,
                "height": h,
                "seconds": (truth.n_frames - 1) * dt,
                "dt": dt,
                "z_true": z_true,
                "z_pred": z_pred,
                "z_error": abs(z_pred - z_true),
                "z_error_pct": 100.0 * abs(z_pred - z_true) / fall,
                "dvz_first": _first_dvz(pred.pos[:, 0, 2], start, dt),
            }
        )
    return rows


def _first_dvz(z: np.ndarray, start: int, dt: float) -> float:
    """``(z_{s+1} − 2 z_s + z_{s−1}) / dt``: the velocity change of the first predicted frame
    ``s + 1``, read from positions. With no history (``s = 0``) no position before the seed
    exists (the seed's velocity, the engine's at the frame's end, is not the mean velocity over
    a frame that positions give), so the second predicted frame's change
    ``(z_2 − 2 z_1 + z_0) / dt`` stands for it (in free flight every frame's is ``−g·dt``)."""
    if start > 0 and len(z) >= start + 2:
        return float((z[start + 1] - 2 * z[start] + z[start - 1]) / dt)
    if start == 0 and len(z) >= 3:
        return float((z[2] - 2 * z[1] + z[0]) / dt)
    return float("nan")
