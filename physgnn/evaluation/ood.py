"""Does a scene lie inside what a run was trained on? One line naming what does not.

The ranges come from the run's own config (``data.scene``: the training family's sphere count,
radius range, density, drop height and initial speed, frame interval and materials: the ranges
of drawn materials, ``material_ranges``, else the fixed ``materials``): spheres in the scene
(a pile of 200 where the training scenes held at most 20 is deeper and denser than any the
network saw), radius, mass
(``density·4/3·π·r³`` over the radius range), speed (up to the initial speed bound plus a free
fall from the highest start), frame interval and each material parameter. A scene value more
than :data:`MARGIN` (relative) outside its range is named; a learned simulator there
extrapolates, and its rollout should be read as such.
"""

from __future__ import annotations

import math

import numpy as np
from omegaconf import OmegaConf

from physgnn.physics.energy import G

MARGIN = 0.1
MATERIAL_KEYS = ("restitution", "lateral_friction", "rolling_friction", "spinning_friction")


def _ball_mass(radius: float, density: float) -> float:
    return density * 4.0 / 3.0 * math.pi * radius**3


def training_ranges(cfg) -> dict[str, tuple[float, float]]:
    """``{quantity: (low, high)}`` of the run config's training family (empty when the config
    names none)."""
    family = OmegaConf.select(cfg, "data.scene") if cfg is not None else None
    if family is None or "radius_min" not in family:
        return {}
    r0, r1, rho = float(family.radius_min), float(family.radius_max), float(family.density)
    fall = math.sqrt(2 * G * float(family.get("h_max", 0.0)))
    ranges = {}
    if "n_min" in family and "n_max" in family:
        ranges["spheres"] = (float(family.n_min), float(family.n_max))
    ranges["radius (m)"] = (r0, r1)
    ranges["mass (kg)"] = (_ball_mass(r0, rho), _ball_mass(r1, rho))
    ranges["speed (m/s)"] = (0.0, float(family.get("max_speed0", 0.0)) + fall)
    ranges["dt (s)"] = (float(family.dt), float(family.dt))
    drawn = family.get("material_ranges") or {}
    for k in MATERIAL_KEYS:
        values = [float(v) for v in drawn[k]] if k in drawn else []
        values = values or [float(m[k]) for m in family.get("materials") or []]
        if values:
            ranges[k] = (min(values), max(values))
    return ranges


def scene_values(scene) -> dict[str, np.ndarray]:
    """The same quantities of a :class:`~physgnn.physics.scene.Scene` at its start."""
    values = {"spheres": np.array([len(scene.radius)]), "radius (m)": scene.radius}
    values["mass (kg)"] = scene.mass
    values["speed (m/s)"] = np.linalg.norm(scene.vel, axis=-1)
    values["dt (s)"] = np.array([scene.dt])
    params = np.asarray(scene.materials)[np.asarray(scene.material)]
    values |= {k: params[:, i] for i, k in enumerate(MATERIAL_KEYS)}
    return values


def outside(scene, cfg) -> list[str]:
    """``"<quantity> a–b (trained on c–d)"`` for every quantity of ``scene`` outside the
    training ranges of the run config ``cfg``."""
    values, found = scene_values(scene), []
    for name, (low, high) in training_ranges(cfg).items():
        v = np.asarray(values[name], dtype=np.float64)
        if v.size == 0:
            continue
        lo, hi = float(v.min()), float(v.max())
        if lo < low - MARGIN * abs(low) - 1e-12 or hi > high + MARGIN * abs(high) + 1e-12:
            found.append(f"{name} {lo:.3g}–{hi:.3g} (trained on {low:.3g}–{high:.3g})")
    return found


def warning_text(name: str, found: list[str]) -> str:
    """The one line that says ``name`` lies outside the training ranges (``found``: what
    :func:`outside` returned)."""
    return (
        f"{name} lies outside what the run was trained on: {'; '.join(found)}; its rollout "
        "is extrapolation"
    )
