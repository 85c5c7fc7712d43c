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

    - ``substeps``: physics steps per frame (step = dt / substeps). 20 at dt 0.1 (5 ms): a
      30 m drop (24 m/s) moves 12 cm per step, about a tenth of a diameter.
    - ``solver_iterations``: sequential-impulse iterations; piles need more than the default.
    - ``contact_erp``: fraction of a contact's penetration removed per step. In pybullet 3.2.7
      this correction is added to the *velocity* (``split_impulse`` measurably changes
      nothing for these bodies), so it injects energy: at the default 0.2 a bounce of
      restitution e reached 1.3–2.5·e² of the drop height. 0.01 keeps the apex ratio within
      4 % of e² while still resolving penetration (half-life ≈ 0.35 s).
    - ``contact_breaking_threshold``: distance (m) at which contacts are created. Bullet's
      default 0.02 creates speculative contacts before impact; the first solve then removes
      the approach speed and the bounce is lost or random. 1 mm: consistent bounces.
    - ``restitution_velocity_threshold``: below this approach speed (m/s) a contact is
      inelastic, so resting spheres stop micro-bouncing.
    - ``sleeping``: Bullet deactivates bodies at rest (2 s below its thresholds); they wake
      when hit. ``ccd``: swept-sphere continuous collision detection (radius ``ccd_ratio·r``).
    - ``erp`` / ``friction_erp``: joint and friction error reduction (Bullet defaults).
    - ``wall_thickness``: thickness of the boxes behind walls and static planes (m).
    """

    substeps: int = 20
    solver_iterations: int = 50
    erp: float = 0.2
    contact_erp: float = 0.01
    friction_erp: float = 0.2
    split_impulse: bool = True
    split_impulse_threshold: float = -0.01
    restitution_velocity_threshold: float = 0.5
    contact_breaking_threshold: float = 0.001
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
