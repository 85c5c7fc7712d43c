"""The pybullet settings of the ground truth (the ``engine`` config), checked."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from physgnn.physics.scene import SceneError


@dataclass(frozen=True)
class EngineSettings:
    """pybullet settings (keys of the ``engine`` config; measurements in README "Physics
    fidelity").

    - ``substeps``: physics steps per frame (step h = dt / substeps). 40 at dt 0.1 (2.5 ms): a
      30 m drop (24 m/s) moves 6 cm per step. Semi-implicit Euler lags free fall by g·h·t/2
      (4.9 cm after 4 s at 2.5 ms, 9.8 cm at 5 ms), and a bounce gains about g·h/v in apex
      ratio from the gravity of its impact step: 40 keeps 8 bounces of e = 0.7 from 20 m
      within 4 % of e² (the former 20 substeps, contact ERP 0.01 and 1 mm threshold: 4.8 and
      5.8 % at the 7th and 8th bounces).
    - ``solver_iterations``: sequential-impulse iterations; piles need more than the default.
    - ``contact_erp``: fraction of a contact's penetration removed per step. In pybullet 3.2.7
      this correction is added to the *velocity* (``split_impulse`` measurably changes
      nothing for these bodies), so it injects energy: at the default 0.2 a bounce of
      restitution e reached 1.3–2.5·e² of the drop height. 0.005 per 2.5 ms step (half-life
      of a penetration ≈ 0.35 s) adds at most 1–2 % to an apex ratio.
    - ``contact_breaking_threshold``: distance (m) at which contacts are created. A positive
      distance makes a speculative contact whose first solve removes the approach speed
      minus distance/h: Bullet's default 0.02 loses bounces at random, and 1 mm still cut a
      bounce by 12–14 % whenever a step ended within 1 mm of the ground. 0.1 mm costs a bounce
      at most 0.1 mm / h = 0.04 m/s: every bounce keeps its restitution (tests/test_oracles.py,
      as with 1e-6), and a sphere pressed against a wall keeps a contact before it overlaps
      (Table 1 static depth 8.7e-6; 1e-6 gave 7.1e-5).
    - ``restitution_velocity_threshold``: below this approach speed (m/s) a contact is
      inelastic, so resting spheres stop micro-bouncing.
    - ``sleeping``: Bullet deactivates bodies at rest (2 s below its thresholds); they wake
      when hit. ``ccd``: swept-sphere continuous collision detection (radius ``ccd_ratio·r``).
    - ``erp`` / ``friction_erp``: joint and friction error reduction (Bullet defaults).
    - ``wall_thickness``: thickness of the boxes behind walls and static planes (m).
    """

    substeps: int = 40
    solver_iterations: int = 50
    erp: float = 0.2
    contact_erp: float = 0.005
    friction_erp: float = 0.2
    split_impulse: bool = True
    split_impulse_threshold: float = -0.01
    restitution_velocity_threshold: float = 0.5
    contact_breaking_threshold: float = 1e-4
    sleeping: bool = True
    ccd: bool = True
    ccd_ratio: float = 0.5
    wall_thickness: float = 1.0

    @classmethod
    def from_cfg(cls, cfg: Mapping | EngineSettings | None) -> EngineSettings:
        if cfg is None:
            return cls()
        if isinstance(cfg, EngineSettings):
            return cfg
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(cfg) - known
        if unknown:
            raise SceneError(f"unknown engine setting(s) {sorted(unknown)}; known: {sorted(known)}")
        s = cls(**{k: cfg[k] for k in cfg})
        if s.substeps < 1 or s.solver_iterations < 1:
            raise SceneError("engine: substeps and solver_iterations must be >= 1")
        return s
