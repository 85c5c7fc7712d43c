"""pybullet ground truth: simulate a :class:`~physgnn.physics.scene.Scene` into a
:class:`~physgnn.physics.scene.Trajectory`.

One DIRECT client per call (always disconnected). Spheres are maximal-coordinate rigid bodies
(``GEOM_SPHERE``); the ground is a ``GEOM_PLANE`` (a half-space: nothing tunnels through it);
walls and static planes are boxes whose top face is the bounded plane and whose thickness lies
behind it. Quaternions are converted from pybullet's (x, y, z, w) here and only here.

Bullet combines the coefficients of two touching bodies: restitution and lateral friction by
product, rolling / spinning friction as ``r0·f1 + r1·f0``: two spheres of restitution ``e``
collide with ``e²``. Each plane gets its row of ``scene.plane_materials`` (None: restitution 1,
lateral friction 1, rolling / spinning friction 0 for every plane, so that a sphere's material
alone sets its sphere–plane contact); a sphere of restitution ``e`` on a plane of ``e_p``
bounces with ``e·e_p``.
See :class:`EngineSettings` for the chosen solver settings and why.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Mapping

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from physgnn.groundtruth.settings import EngineSettings
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import GROUND, Scene, as_float32, default_plane_materials
from physgnn.physics.trajectory import Trajectory


def _import_pybullet_quietly():
    """Import pybullet without its "build time" line (C printf), so CLIs keep one-line errors."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        import pybullet
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)
    return pybullet


p = _import_pybullet_quietly()

# Inertia factor (× m·r²) of spheres whose rotation is off: rotation takes no energy.
LOCKED_INERTIA = 1e6


def engine_version() -> str:
    """pybullet's API version, stored in every trajectory."""
    return f"pybullet {p.getAPIVersion()}"


def plane_box_pose(row: np.ndarray, thickness: float):
    """Box half extents, centre and (x, y, z, w) orientation for a bounded plane row ``[11]``:
    local x = reference direction, y = normal × reference, z = normal; the box's +z face is
    the plane."""
    row = np.asarray(row, dtype=np.float64)
    centre, n, d = row[:3], row[3:6], row[6:9]
    rot = np.stack([d, np.cross(n, d), n], axis=1)
    quat = Rotation.from_matrix(rot).as_quat()  # (x, y, z, w)
    half = [float(row[9]), float(row[10]), thickness / 2]
    return half, (centre - n * thickness / 2).tolist(), quat.tolist()


def _add_planes(scene: Scene, s: EngineSettings, cid: int) -> list[int]:
    ids = []
    coefficients = (
        default_plane_materials(len(scene.planes))
        if scene.plane_materials is None
        else scene.plane_materials
    )
    for row, kind, mat in zip(scene.planes, scene.plane_kind, coefficients, strict=True):
        if kind == GROUND:
            shape = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
            body = p.createMultiBody(0, shape, basePosition=row[:3].tolist(), physicsClientId=cid)
        else:
            half, centre, quat = plane_box_pose(row, s.wall_thickness)
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
            body = p.createMultiBody(
                0, shape, basePosition=centre, baseOrientation=quat, physicsClientId=cid
            )
        p.changeDynamics(
            body,
            -1,
            restitution=float(mat[0]),
            lateralFriction=float(mat[1]),
            rollingFriction=float(mat[2]),
            spinningFriction=float(mat[3]),
            physicsClientId=cid,
        )
        ids.append(body)
    return ids


def _add_spheres(scene: Scene, s: EngineSettings, cid: int) -> list[int]:
    eff = scene.effects
    quat_xyzw = Q.to_xyzw(torch.as_tensor(scene.quat, dtype=torch.float64)).numpy()
    ids = []
    for i in range(scene.n_spheres):
        r = float(scene.radius[i])
        shape = p.createCollisionShape(p.GEOM_SPHERE, radius=r, physicsClientId=cid)
        body = p.createMultiBody(
            float(scene.mass[i]),
            shape,
            basePosition=scene.pos[i].tolist(),
            baseOrientation=quat_xyzw[i].tolist(),
            useMaximalCoordinates=True,
            physicsClientId=cid,
        )
        mat = scene.materials[int(scene.material[i])]
        friction = mat[1:4] if eff.friction else np.zeros(3)
        kwargs = dict(
            restitution=float(mat[0]),
            lateralFriction=float(friction[0]),
            rollingFriction=float(friction[1]),
            spinningFriction=float(friction[2]),
            linearDamping=0.0,
            angularDamping=0.0,
        )
        if s.ccd:
            kwargs["ccdSweptSphereRadius"] = s.ccd_ratio * r
        if not eff.rotation:
            # A huge inertia takes no energy into rotation; orientation is also reset each step.
            # (pybullet zeroes a maximal-coordinate body's mass unless it is passed again.)
            kwargs["mass"] = float(scene.mass[i])
            kwargs["localInertiaDiagonal"] = [LOCKED_INERTIA * float(scene.mass[i]) * r * r] * 3
        p.changeDynamics(body, -1, physicsClientId=cid, **kwargs)
        state = (
            p.ACTIVATION_STATE_ENABLE_SLEEPING
            if s.sleeping
            else (p.ACTIVATION_STATE_DISABLE_SLEEPING)
        )
        p.changeDynamics(body, -1, activationState=state, physicsClientId=cid)
        angvel = scene.angvel[i].tolist() if eff.rotation else [0.0, 0.0, 0.0]
        p.resetBaseVelocity(body, scene.vel[i].tolist(), angvel, physicsClientId=cid)
        ids.append(body)
    return ids


def _configure(scene: Scene, s: EngineSettings, cid: int) -> None:
    p.setGravity(
        *(scene.gravity if scene.effects.gravity else (0.0, 0.0, 0.0)), physicsClientId=cid
    )
    p.setPhysicsEngineParameter(
        fixedTimeStep=scene.dt / s.substeps,
        numSubSteps=0,
        numSolverIterations=s.solver_iterations,
        erp=s.erp,
        contactERP=s.contact_erp,
        frictionERP=s.friction_erp,
        useSplitImpulse=int(s.split_impulse),
        splitImpulsePenetrationThreshold=s.split_impulse_threshold,
        restitutionVelocityThreshold=s.restitution_velocity_threshold,
        contactBreakingThreshold=s.contact_breaking_threshold,
        deterministicOverlappingPairs=1,
        physicsClientId=cid,
    )


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


def _filter_contacts(scene: Scene, spheres: list[int], planes: list[int], cid: int) -> None:
    """Switch off the contacts a scene does not call for. Pair filters, because pybullet's
    group / mask filtering did not stop sphere–plane contacts (measured)."""
    if not scene.effects.surface_contact:
        for a in spheres:
            for b in planes:
                p.setCollisionFilterPair(a, b, -1, -1, 0, physicsClientId=cid)
    if not scene.effects.sphere_contact:
        for k, a in enumerate(spheres):
            for b in spheres[k + 1 :]:
                p.setCollisionFilterPair(a, b, -1, -1, 0, physicsClientId=cid)


def _run(scene: Scene, s: EngineSettings, cid: int, on_frame=None) -> tuple[np.ndarray, ...]:
    _configure(scene, s, cid)
    planes = _add_planes(scene, s, cid)
    ids = _add_spheres(scene, s, cid)
    _filter_contacts(scene, ids, planes, cid)
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
        _configure(scene, s, cid)
        frame = _read(_add_spheres(scene, s, cid), cid)
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
        _configure(scene, s, cid)
        planes = _add_planes(scene, s, cid)
        ids = _add_spheres(scene, s, cid)
        _filter_contacts(scene, ids, planes, cid)
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
