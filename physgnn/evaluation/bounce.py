"""Bounces against restitution: one sphere per material dropped on the ground.

A sphere of restitution ``e`` dropped from rest at drop height ``H`` (its bottom above the
ground) rises after the first impact to ``e²·H``. Each row rolls the learned simulator out
from the analytic free-fall seed frames of a sphere of that material (:func:`free_fall`) until
the apex after the first bounce, and reports ``ratio = apex / (e²·H)`` (1 is exact) beside
the same ratio of pybullet (:func:`physgnn.groundtruth.oracles.bounce_ratios`, its physics
steps, the engine settings of the datasets). The apex is read from the rollout's frames with
the flight invariant of semi-implicit Euler (:func:`~physgnn.groundtruth.oracles.apex_heights`).
Rows of ``bounce.csv`` and the report's bounce section.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence

import numpy as np

from physgnn.errors import ConfigError
from physgnn.evaluation.freefall import free_fall
from physgnn.groundtruth.oracles import apex_heights, bounce_ratios
from physgnn.physics.energy import G
from physgnn.ranges import number
from physgnn.rollout import rollout

# A material of the eval's bounce config (conf/eval.yaml: bounce.materials) and its values: the
# restitution above 0 (the row divides the apex by e²·height), every friction from 0.
MATERIAL = {
    "restitution": number(0, 1, above=True, what="the apex is e² of the drop"),
    "lateral_friction": number(0),
    "rolling_friction": number(0),
    "spinning_friction": number(0),
}
MATERIAL_FIX = (
    "e.g. {restitution: 0.5, lateral_friction: 0.5, rolling_friction: 0.01, "
    "spinning_friction: 0.01}"
)
# The eval's bounce settings: drop height (the sphere's bottom), radius and frame step
SETTINGS = {
    "height": number(0, above=True, what="m, the sphere's bottom above the ground", example=10.0),
    "radius": number(0, above=True, what="m", example=0.75),
    "dt": number(0, above=True, what="s between frames", example=0.1),
}


def check_settings(cfg) -> tuple[list[list[float]], float, float, float] | None:
    """``(materials [K, 4], height, dt, radius)`` of the eval's ``bounce`` config (None: not
    measured), each value refused in one line naming its key (:data:`SETTINGS`,
    :data:`MATERIAL`)."""
    if cfg is None:
        return None
    values = {k: float(a.check(f"bounce.{k}", cfg.get(k))) for k, a in SETTINGS.items()}
    materials = cfg.get("materials")
    if not isinstance(materials, Sequence) or isinstance(materials, str):
        raise ConfigError(
            f"bounce.materials must be a list of materials ({', '.join(MATERIAL)}), got "
            f"{materials!r} (the default: bounce.materials=${{bounce.scene.materials}})"
        )
    rows = [_material(f"bounce.materials[{i}]", m) for i, m in enumerate(materials)]
    return rows, values["height"], values["dt"], values["radius"]


def _material(key: str, material) -> list[float]:
    """``[restitution, lateral, rolling, spinning friction]`` of one material of the config."""
    if not isinstance(material, Mapping) or set(material) != set(MATERIAL):
        raise ConfigError(
            f"{key} must be a material of the keys {', '.join(MATERIAL)}, got {material!r} "
            f"({MATERIAL_FIX})"
        )
    return [float(a.check(f"{key}.{k}", material[k], MATERIAL_FIX)) for k, a in MATERIAL.items()]


def bounce_rows(
    name: str,
    simulator,
    materials,
    height: float,
    dt: float,
    radius: float,
    mass: float | None = None,
    **kwargs,
) -> list[dict]:
    """One row per material (``materials [K, 4]``: restitution, lateral, rolling, spinning
    friction) for a sphere of ``radius`` (and ``mass`` kg; None: density 1 000) whose bottom
    starts ``height`` m above the ground; keyword arguments go to
    :func:`physgnn.rollout.rollout`. Rows carry the sphere's ``mass``."""
    materials = np.asarray(materials, np.float64).reshape(-1, 4)
    fall = math.sqrt(2.0 * height / G)
    rows = []
    for material in materials:
        e = float(material[0])
        seconds = dt * math.ceil((fall * (1.0 + 2.0 * e) + 0.5) / dt)  # impact, apex and more
        seed = dataclasses.replace(
            free_fall(height + radius, seconds, dt, radius), materials=material[None]
        )
        if mass is not None:
            seed = dataclasses.replace(seed, mass=np.full(1, float(mass)))
        (pred,) = rollout(simulator, [seed], **kwargs)
        apex = _first_apex(pred, radius, dt)
        truth = _truth_ratio(e, height, radius, dt)
        rows.append(
            {
                "run": name,
                "restitution": e,
                "mass": float(seed.mass[0]),
                "height": height,
                "apex": apex,
                "ratio": apex / (e * e * height),
                "truth_ratio": truth,
                "diverged_at": pred.diverged_at,
            }
        )
    return rows


@functools.cache
def _truth_ratio(e: float, height: float, radius: float, dt: float) -> float:
    """pybullet's first apex ratio (1 is exact), once per material and drop for all runs."""
    ratios = bounce_ratios(e, height=height, radius=radius, dt=dt)
    return float(ratios[0]) if ratios.size else float("nan")


def _first_apex(pred, radius: float, dt: float) -> float:
    """Height of the sphere's bottom at the apex after its first bounce (NaN: none)."""
    z = np.asarray(pred.pos[:, 0, 2], np.float64) - radius
    # the frames' own finite differences, whatever the model's state: in flight they fall by
    # g·dt a frame, the invariant of semi-implicit Euler at step dt (an engine state's end
    # velocities follow the engine's substeps instead)
    vz = np.concatenate([[float(pred.vel[0, 0, 2])], np.diff(z) / dt])
    if not ((vz[:-1] <= 0) & (vz[1:] > 0)).any():  # never moved up again: no bounce
        return float("nan")
    apex = apex_heights(z, vz, dt)
    return float(apex[0]) if apex.size else float("nan")
