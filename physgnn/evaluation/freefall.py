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
from collections.abc import Sequence

import numpy as np

from physgnn.errors import ConfigError
from physgnn.physics.energy import G
from physgnn.physics.scene import Effects, ground_plane
from physgnn.physics.trajectory import Trajectory
from physgnn.ranges import number
from physgnn.rollout import rollout

DENSITY = 1000.0  # kg/m³, that of the training scenes
RADIUS = 0.5  # m, the falling sphere's
# The eval's freefall settings (conf/eval.yaml: freefall); the heights' bound follows floor and dt
DT = number(0, above=True, what="s between frames", example=0.1)
FLOOR = number(RADIUS, what="m: the sphere's centre, kept off the ground", example=5.0)
FIX = "e.g. freefall.heights=[10.0, 100.0, 1000.0]"


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


def free_fall(height: float, seconds: float, dt: float, radius: float = RADIUS) -> Trajectory:
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


def check_settings(cfg) -> tuple[list[float], float, float, float] | None:
    """``(heights, seconds, dt, floor)`` of the eval's ``freefall`` config (None: not
    measured), each refused in one line naming its key: ``dt`` > 0, ``floor`` at least the
    sphere's radius (lower, the fall would reach the ground), ``seconds`` at least one frame
    and every height at least one frame's fall above ``floor`` (a fall of no frame has nothing
    to measure)."""
    if cfg is None:
        return None
    dt = float(DT.check("freefall.dt", cfg.get("dt")))
    floor = float(FLOOR.check("freefall.floor", cfg.get("floor")))
    seconds = number(dt, what="s: at least one frame of freefall.dt", example=4.0)
    seconds = float(seconds.check("freefall.seconds", cfg.get("seconds")))
    heights = cfg.get("heights")
    if not isinstance(heights, Sequence) or isinstance(heights, str):
        raise ConfigError(
            f"freefall.heights must be a list of heights (m), got {heights!r} ({FIX})"
        )
    what = f"m: at least one frame's fall, g·dt²/2, above freefall.floor={floor:g}"
    height = number(floor + 0.5 * G * dt**2, what=what)
    heights = [height.check(f"freefall.heights[{i}]", h, FIX) for i, h in enumerate(heights)]
    return [float(h) for h in heights], seconds, dt, floor


def check_frames(heights, seconds: float, dt: float, floor: float, history: int, run: str) -> None:
    """Every fall of :func:`check_settings`'s ``(heights, seconds, dt, floor)`` lasts more
    frames than the ``history`` + 1 seed frames of ``run`` (else its row would measure the
    seed, not a prediction); refused in one line naming the height."""
    for i, height in enumerate(heights):
        frames = round(free_seconds(height, seconds, dt, floor) / dt)
        if frames <= history:
            least = floor + 0.5 * G * ((history + 1) * dt) ** 2
            raise ConfigError(
                f"freefall.heights[{i}]={height:g} gives {frames} frame(s) of fall (above "
                f"freefall.floor={floor:g}, within freefall.seconds={seconds:g}) and run {run} "
                f"needs {history + 1} (its H + 1 = {history + 1} seed frames, then one to "
                f"predict): give heights from {least:g} m and freefall.seconds from "
                f"{(history + 1) * dt:g}"
            )


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
