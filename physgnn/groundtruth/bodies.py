"""A scene's bodies in a pybullet client: the quiet import of pybullet, the solver settings of
:class:`~physgnn.groundtruth.settings.EngineSettings`, the planes, the spheres with their
materials, and the contacts a scene's effects switch off.

Spheres are maximal-coordinate rigid bodies (``GEOM_SPHERE``); the ground is a ``GEOM_PLANE``
(a half-space: nothing tunnels through it); walls and static planes are boxes whose top face is
the bounded plane and whose thickness lies behind it.

Bullet combines the coefficients of two touching bodies: restitution and lateral friction by
product, rolling / spinning friction as ``r0·f1 + r1·f0``: two spheres of restitution ``e``
collide with ``e²``. Each plane gets its row of ``scene.plane_materials`` (None: restitution 1,
lateral friction 1, rolling / spinning friction 0 for every plane, so that a sphere's material
alone sets its sphere–plane contact); a sphere of restitution ``e`` on a plane of ``e_p``
bounces with ``e·e_p``.
"""

from __future__ import annotations

import os
import sys

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from physgnn.groundtruth.settings import EngineSettings
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import GROUND, Scene, default_plane_materials


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


def make_bodies(scene: Scene, s: EngineSettings, cid: int) -> list[int]:
    """Client ``cid`` set up for ``scene``: its settings, planes and spheres, and the contacts
    its effects switch off; the spheres' body ids."""
    configure(scene, s, cid)
    planes = add_planes(scene, s, cid)
    spheres = add_spheres(scene, s, cid)
    filter_contacts(scene, spheres, planes, cid)
    return spheres


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


def add_planes(scene: Scene, s: EngineSettings, cid: int) -> list[int]:
    """The body ids of the scene's planes, each with its materials (module doc)."""
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


def add_spheres(scene: Scene, s: EngineSettings, cid: int) -> list[int]:
    """The body ids of the scene's spheres at its start, with their materials (friction only
    with the ``friction`` effect; a locked inertia without ``rotation``)."""
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
            else p.ACTIVATION_STATE_DISABLE_SLEEPING
        )
        p.changeDynamics(body, -1, activationState=state, physicsClientId=cid)
        angvel = scene.angvel[i].tolist() if eff.rotation else [0.0, 0.0, 0.0]
        p.resetBaseVelocity(body, scene.vel[i].tolist(), angvel, physicsClientId=cid)
        ids.append(body)
    return ids


def configure(scene: Scene, s: EngineSettings, cid: int) -> None:
    """Gravity (with the ``gravity`` effect) and the solver settings ``s`` of client ``cid``."""
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


def filter_contacts(scene: Scene, spheres: list[int], planes: list[int], cid: int) -> None:
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
