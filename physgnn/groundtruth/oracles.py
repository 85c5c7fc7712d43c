"""Analytic oracles for the pybullet ground truth: tiny scenes whose answer is known.

Used by the tests (``tests/test_oracles.py``) and by the bench's engine table. Each function
simulates one small scene with :func:`physgnn.groundtruth.engine.simulate` and returns the measured
quantity next to its analytic value:

- :func:`bounce_ratios`: successive apex heights of a bouncing sphere, divided by ``e²``.
- :func:`free_fall_error`: distance between the engine and ``z0 − ½gt²`` after ``t`` seconds.
- :func:`head_on_momentum_error`: momentum change across a head-on impact of two frictionless
  spheres (no gravity), relative to the momentum before.
- :func:`ramp_travel`: distance a sphere (rotation locked: it can only slide) starting at rest
  on a tilted plane travels down it in a given time.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.settings import EngineSettings
from physgnn.physics.energy import G
from physgnn.physics.scene import GROUND, STATIC, Effects, Scene, ground_plane, make_plane


def sphere_scene(
    pos,
    *,
    vel=None,
    radius=0.5,
    mass=None,
    material=(0.5, 0.5, 0.0, 0.0),
    dt: float = 0.1,
    n_frames: int = 20,
    planes=None,
    effects: Effects | None = None,
) -> Scene:
    """Spheres of one material over the ground (plus ``planes``, kind static).

    pos, vel ``[N, 3]``; radius, mass scalars or ``[N]`` (mass defaults to 1 kg each).
    """
    pos = np.asarray(pos, dtype=np.float32).reshape(-1, 3)
    n = len(pos)
    zeros = np.zeros((n, 3), np.float32)
    rows = [ground_plane(), *(planes or [])]
    return Scene(
        name="oracle",
        radius=np.broadcast_to(np.asarray(radius, np.float32), (n,)).copy(),
        mass=np.broadcast_to(np.asarray(1.0 if mass is None else mass, np.float32), (n,)).copy(),
        material=np.zeros(n, np.int64),
        pos=pos,
        quat=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
        vel=zeros if vel is None else np.asarray(vel, np.float32).reshape(n, 3),
        angvel=zeros.copy(),
        planes=np.stack(rows).astype(np.float32),
        plane_kind=np.array([GROUND] + [STATIC] * (len(rows) - 1)),
        materials=np.array([material], np.float32),
        dt=dt,
        n_frames=n_frames,
        effects=effects or Effects(),
    )


def apex_heights(z: np.ndarray, vz: np.ndarray, h: float) -> np.ndarray:
    """Apex of each flight after a bounce from states at every physics step ``h``.

    z (height of the sphere's bottom), vz ``[T]``. Semi-implicit Euler conserves
    ``z + vz²/2g − h·vz/2`` exactly in flight, so this invariant, read at the highest state of
    each flight, is the apex of that flight. Returns ``[B]``, one per bounce.
    """
    z, vz = np.asarray(z, np.float64), np.asarray(vz, np.float64)
    invariant = z + vz**2 / (2 * G) - h * vz / 2
    up = np.nonzero((vz[:-1] <= 0) & (vz[1:] > 0))[0] + 1  # first step moving up again
    ends = [*up[1:], len(z)]
    return np.array([invariant[a + int(np.argmax(z[a:b]))] for a, b in zip(up, ends, strict=True)])


def bounce_ratios(
    e: float,
    *,
    height: float = 20.0,
    offset: float = 0.0,
    radius: float = 0.5,
    dt: float = 0.1,
    engine: Mapping | None = None,
) -> np.ndarray:
    """Apex ratios ``h_{k+1} / h_k / e²`` (``h_0`` = drop height) of a sphere of restitution
    ``e`` dropped from rest; 1 is exact. ``offset``: the drop height is adjusted so that a
    physics step ends ``offset`` m above the ground just before the first impact (0.3 mm
    reproduces the early contact a 1 mm contact-breaking threshold made). ``[B]``."""
    s = EngineSettings.from_cfg(engine)
    h = dt / s.substeps
    n = int(np.sqrt(2 * height / G) / h)
    drop = offset + G * h**2 * n * (n + 1) / 2  # semi-implicit Euler: fall after n steps
    flight = 2 * np.sqrt(2 * drop / G)
    n_steps = int((flight / 2 + flight * e / (1 - e)) / h) + 60  # every flight, then rest
    scene = sphere_scene(
        [0, 0, radius + drop],
        radius=radius,
        material=(e, 0.5, 0.0, 0.0),
        dt=h,
        n_frames=n_steps,
    )
    traj = simulate(scene, {**(engine or {}), "substeps": 1})  # one frame per physics step
    apex = apex_heights(traj.pos[:, 0, 2] - radius, traj.vel[:, 0, 2], h)
    heights = np.concatenate([[drop], apex])
    return heights[1:] / heights[:-1] / e**2


def impact_speeds(e: float, height: float, count: int) -> np.ndarray:
    """Analytic impact speeds ``[count]`` of the first bounces: ``√(2gH)·e^k``."""
    return np.sqrt(2 * G * height) * e ** np.arange(count)


def free_fall_error(substeps: int, seconds: float = 4.0, dt: float = 0.1) -> float:
    """|z_engine − (z0 − ½gt²)| (m) after ``seconds`` of free fall at ``substeps`` per frame.

    Semi-implicit Euler lags by ``g·h·t/2`` (h = dt/substeps): 9.8 cm at 5 ms after 4 s."""
    frames = int(round(seconds / dt)) + 1
    z0 = G * seconds**2  # high enough never to land
    traj = simulate(sphere_scene([0, 0, z0], dt=dt, n_frames=frames), {"substeps": substeps})
    t = (frames - 1) * dt
    return float(abs(traj.pos[-1, 0, 2] - (z0 - G * t**2 / 2)))


def head_on_momentum_error(
    e: float = 0.7, masses=(1.0, 3.0), speeds=(4.0, -2.0), engine: Mapping | None = None
) -> tuple[float, np.ndarray]:
    """Two frictionless spheres, no gravity, meet head-on along x.

    Returns (|Δp| / |p| over the impact, velocities after ``[2]`` along x). Bullet combines
    restitution by product: the pair collides with ``e²``."""
    r = 0.5
    eff = Effects(gravity=False, friction=False)
    scene = sphere_scene(
        [[-2.0, 0, 5], [2.0, 0, 5]],
        vel=[[speeds[0], 0, 0], [speeds[1], 0, 0]],
        radius=r,
        mass=np.asarray(masses),
        material=(e, 0.0, 0.0, 0.0),
        n_frames=21,
        effects=eff,
    )
    traj = simulate(scene, engine)
    m = np.asarray(masses, np.float64)[:, None]
    p0 = (m * traj.vel[0].astype(np.float64)).sum(0)
    p1 = (m * traj.vel[-1].astype(np.float64)).sum(0)
    return float(np.linalg.norm(p1 - p0) / np.linalg.norm(p0)), traj.vel[-1, :, 0].copy()


def head_on_analytic(e_pair: float, masses, speeds) -> np.ndarray:
    """Velocities after a 1-D impact with restitution ``e_pair`` ``[2]``."""
    (m1, m2), (u1, u2) = masses, speeds
    p = m1 * u1 + m2 * u2
    v1 = (p + m2 * e_pair * (u2 - u1)) / (m1 + m2)
    v2 = (p + m1 * e_pair * (u1 - u2)) / (m1 + m2)
    return np.array([v1, v2])


def ramp_travel(
    slope_deg: float, friction: float, seconds: float = 1.0, engine: Mapping | None = None
) -> float:
    """Distance (m) a sphere released at rest on a plane tilted by ``slope_deg`` travels in
    ``seconds``, rotation locked (it slides or stays like a block: analytic travel
    ``½·g·(sin θ − μ cos θ)·t²`` when ``tan θ > μ``, else 0)."""
    a, r = np.deg2rad(slope_deg), 0.5
    normal = np.array([np.sin(a), 0.0, np.cos(a)])
    downhill = np.array([np.cos(a), 0.0, -np.sin(a)])
    centre = np.array([0.0, 0.0, 10.0])
    plane = make_plane(centre, normal, downhill, 20.0, 5.0)
    start = centre - 10.0 * downhill + r * normal
    frames = int(round(seconds / 0.1)) + 1
    scene = sphere_scene(
        start,
        radius=r,
        material=(0.0, friction, 0.0, 0.0),
        n_frames=frames,
        planes=[plane],
        effects=Effects(rotation=False),
    )
    traj = simulate(scene, engine)
    return float((traj.pos[-1, 0] - traj.pos[0, 0]) @ downhill)


def ramp_analytic(slope_deg: float, friction: float, seconds: float = 1.0) -> float:
    a = np.deg2rad(slope_deg)
    acc = G * (np.sin(a) - friction * np.cos(a))
    return float(max(acc, 0.0) * seconds**2 / 2)
