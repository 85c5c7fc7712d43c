"""pybullet ground truth: simulate a :class:`~physgnn.physics.scene.Scene` into a
:class:`~physgnn.physics.scene.Trajectory`.

One DIRECT client per call (always disconnected), its bodies made by
:mod:`physgnn.groundtruth.bodies`. Quaternions are converted from pybullet's (x, y, z, w) only
here and there. See :class:`EngineSettings` for the chosen solver settings and why.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
import torch

from physgnn.groundtruth.bodies import add_spheres, configure, make_bodies, p
from physgnn.groundtruth.settings import EngineSettings
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import Scene, as_float32
from physgnn.physics.trajectory import Trajectory


def engine_version() -> str:
    """pybullet's API version, stored in every trajectory."""
    return f"pybullet {p.getAPIVersion()}"


def _read(ids: list[int], cid: int) -> tuple[np.ndarray, ...]:
    pos, quat, vel, angvel = [], [], [], []
    for body in ids:
        x, q = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        v, w = p.getBaseVelocity(body, physicsClientId=cid)
        pos.append(x)
        quat.append(q)
        vel.append(v)
        angvel.append(w)
    return tuple(np.asarray(a, dtype=np.float64) for a in (pos, quat, vel, angvel))


def _lock_rotation(ids: list[int], pos: np.ndarray, quat0: list, cid: int) -> None:
    for body, x, q in zip(ids, pos, quat0, strict=True):
        v, _ = p.getBaseVelocity(body, physicsClientId=cid)
        p.resetBasePositionAndOrientation(body, x.tolist(), q, physicsClientId=cid)
        p.resetBaseVelocity(body, v, [0.0, 0.0, 0.0], physicsClientId=cid)


def _run(scene: Scene, s: EngineSettings, cid: int, on_frame=None) -> tuple[np.ndarray, ...]:
    ids = make_bodies(scene, s, cid)
    quat0 = [p.getBasePositionAndOrientation(b, physicsClientId=cid)[1] for b in ids]
    frames = [_read(ids, cid)]
    for _ in range(scene.n_frames - 1):
        _advance(scene, s, ids, quat0, cid)
        frames.append(_read(ids, cid))
        if on_frame is not None:
            on_frame(len(frames))
    return tuple(np.stack(a) for a in zip(*frames, strict=True))


def _advance(scene: Scene, s: EngineSettings, ids: list[int], quat0: list, cid: int) -> None:
    """One frame: ``s.substeps`` engine steps (orientations held at ``quat0`` without
    rotation)."""
    for _ in range(s.substeps):
        p.stepSimulation(physicsClientId=cid)
        if not scene.effects.rotation:
            _lock_rotation(ids, _read(ids, cid)[0], quat0, cid)


def as_stored(scene: Scene, engine_cfg: Mapping | EngineSettings | None = None) -> Scene:
    """``scene`` with its start as a trajectory of it stores frame 0: pybullet's own reading
    of the bodies it creates, rounded to float32. pybullet keeps an orientation as a rotation
    matrix and hands back a normalised quaternion, perhaps negated, which float32 then rounds:
    a scene simulated from its generator's quaternions drifts from one simulated from the
    stored frame 0 (a pile on ramps parted after 22 frames). Simulating this scene instead
    makes the stored start the simulated one, so the truth replays from its own frame 0."""
    s = EngineSettings.from_cfg(engine_cfg)
    scene.validate()
    cid = p.connect(p.DIRECT)
    try:
        configure(scene, s, cid)
        frame = _read(add_spheres(scene, s, cid), cid)
    finally:
        p.disconnect(cid)
    return dataclasses.replace(scene, **_stored(scene, *frame))


def _stored(scene: Scene, pos, quat, vel, angvel) -> dict[str, np.ndarray]:
    """Frames as a trajectory stores them: float32, quaternions (w, x, y, z), no angular
    velocity without rotation."""
    quat = Q.from_xyzw(torch.from_numpy(quat)).numpy()
    if not scene.effects.rotation:
        angvel = np.zeros_like(angvel)
    return {
        "pos": as_float32(pos),
        "quat": as_float32(quat),
        "vel": as_float32(vel),
        "angvel": as_float32(angvel),
    }


def simulate(
    scene: Scene, engine_cfg: Mapping | EngineSettings | None = None, on_frame=None
) -> Trajectory:
    """Run ``scene`` in pybullet for ``scene.n_frames`` frames (frame 0 = initial state);
    ``on_frame(frames done)`` after each frame (a progress display).

    Returns a trajectory with pos, vel, angvel ``[T, N, 3]`` (engine velocities, world frame)
    and quat ``[T, N, 4]`` (w, x, y, z), float32.
    """
    s = EngineSettings.from_cfg(engine_cfg)
    scene.validate()
    cid = p.connect(p.DIRECT)
    try:
        frames = _run(scene, s, cid, on_frame)
    finally:
        p.disconnect(cid)
    gravity = scene.gravity if scene.effects.gravity else (0.0, 0.0, 0.0)
    return Trajectory(
        name=scene.name,
        **_stored(scene, *frames),
        radius=as_float32(scene.radius),
        mass=as_float32(scene.mass),
        material=np.asarray(scene.material, dtype=np.int64),
        planes=as_float32(scene.planes),
        plane_kind=np.asarray(scene.plane_kind, dtype=np.int64),
        materials=as_float32(scene.materials),
        plane_materials=None
        if scene.plane_materials is None
        else as_float32(scene.plane_materials),
        dt=float(scene.dt),
        effects=scene.effects,
        attrs={
            "gravity": list(gravity),
            "substeps": s.substeps,
            "engine": engine_version(),
            "engine_settings": dataclasses.asdict(s),
        },
    )


def one_frame_from(
    scene: Scene, starts, engine_cfg: Mapping | EngineSettings | None = None
) -> np.ndarray:
    """pybullet one frame on from each of ``starts``: ``[len(starts), N, 3]`` positions.

    ``scene`` gives the bodies (its spheres, planes, materials, dt, effects, gravity); each
    start is ``(pos [N, 3], quat [N, 4] (w, x, y, z), vel [N, 3], angvel [N, 3])``. The bodies
    are made once, in one client: each start resets their positions, orientations and
    velocities and wakes them (a body asleep keeps still whatever velocity it is given), as a
    fresh engine would start; Bullet's contact cache carries over from the previous start's
    frame, as it does within one run. From the frames of a run at its own settings, the next
    frames again (to float32 rounding and that cache).
    """
    s = EngineSettings.from_cfg(engine_cfg)
    scene.validate()
    cid = p.connect(p.DIRECT)
    try:
        ids = make_bodies(scene, s, cid)
        out = []
        for pos, quat, vel, angvel in starts:
            quat0 = _restart(ids, pos, quat, vel, angvel if scene.effects.rotation else None, cid)
            _advance(scene, s, ids, quat0, cid)
            out.append(_read(ids, cid)[0])
    finally:
        p.disconnect(cid)
    return np.stack(out) if out else np.zeros((0, scene.n_spheres, 3))


def _restart(ids: list[int], pos, quat, vel, angvel, cid: int) -> list:
    """Set every body's state (``angvel`` None: zero) and wake it; returns the orientations
    as pybullet's (x, y, z, w) lists."""
    quat_xyzw = Q.to_xyzw(torch.as_tensor(np.asarray(quat, np.float64))).tolist()
    spin = np.zeros((len(ids), 3)) if angvel is None else np.asarray(angvel, np.float64)
    for k, body in enumerate(ids):
        p.resetBasePositionAndOrientation(
            body, np.asarray(pos[k], np.float64).tolist(), quat_xyzw[k], physicsClientId=cid
        )
        v = np.asarray(vel[k], np.float64).tolist()
        p.resetBaseVelocity(body, v, spin[k].tolist(), physicsClientId=cid)
        p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_WAKE_UP, physicsClientId=cid)
    return quat_xyzw
