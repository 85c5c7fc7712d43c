"""The options of :class:`~physgnn.models.learned.LearnedSimulator` in two groups, each a
frozen dataclass: the one source of its defaults, units and ranges. Each is mirrored by one
node of ``conf/model/baseline.yaml`` (``model.inputs``, ``model.contacts``: its keys are the
fields, Hydra builds it from its ``_target_``); a value out of range is refused when the group
is made (:func:`physgnn.ranges.check_fields`: a field's range is its metadata), in one line
naming the key (:class:`~physgnn.errors.ConfigError`, a ``ValueError``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from physgnn.ranges import check_fields, number, ranged, whole


@dataclass(frozen=True)
class ModelInputs:
    """What the network sees beyond the velocity histories, radius and mass.

    ``boundary_features``: each sphere's distance to the nearest plane along ±x, ±y, ±z,
    clipped at ``boundary_radius`` (m) and divided by it (the GNS-style baseline's);
    ``contact_features``: pp signed gap and normal relative speed, ps clearance, normal and
    tangential speed; ``material_features``: each sphere's restitution and friction values;
    ``relative_pairs``: pp edges carry relative quantities only; ``mass_ratio``: masses only as
    the pair ratio m_i / (m_i + m_j); ``plane_materials``: ps edges carry the sphere–plane
    contact's restitution and friction (needs ``material_features``); ``engine_state``: the
    state's velocities are the engine's at each frame's end (the dataset's ``vel``,
    ``angvel``), and the model predicts the frame's mean motion apart from the end velocities
    (false: finite-difference velocities, the report's state; :mod:`physgnn.models.learned`)."""

    NODE: ClassVar[str] = "model.inputs"
    boundary_features: bool = False
    boundary_radius: float = ranged(number(0, above=True, what="m"), default=2.0)
    contact_features: bool = True
    material_features: bool = True
    relative_pairs: bool = True
    mass_ratio: bool = True
    plane_materials: bool = True
    engine_state: bool = True

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class ContactHandling:
    """How a step treats contacts (:mod:`physgnn.models.learned`'s module doc).

    ``gravity_prior``: spheres out of reach of any contact fly ballistically;
    ``contact_passes`` K: at most K rebuilds of the graph on a pass's provisional velocities
    (0: one pass); ``pair_impulses``: sphere–sphere interactions decoded as antisymmetric pair
    impulses; ``rest_decision``: a 7th output, the logit of "at rest next frame" (|v| and
    |ω|·r below ``rest_speed``, m/s); ``recent_contact``: the previous default's latch;
    ``contact_memory``: the rules also link by the last frame's motion reversed;
    ``plane_floor``: the planes answer after the pair impulses, each ps edge a one-sided floor,
    then the node decoder's learned restitution and friction (with ``pair_impulses``;
    :mod:`physgnn.models.floor`); ``plane_newton``: with the floor, the planes by Newton's
    law: a sphere arriving in free flight rebounds with its contact's restitution in closed
    form, the network's change on top where a plane stops the sphere (the engine state;
    :func:`physgnn.models.floor.free_bounce`), and after that change the move still may not
    cross a plane; ``pair_floor`` (opt-in): after the pair impulses and the node decoder's
    change, no pp pair's move closes its gap past contact, momentum kept
    (:mod:`physgnn.models.pair_floor`); ``pair_newton`` (opt-in, the engine state): a pp
    pair away from the planes that meets within the frame in free flight takes Newton's
    restitution impulse in closed form, the network's pair impulses on top
    (:mod:`physgnn.models.pair_newton`); ``incremental_passes``: a pass after a rebuild
    recomputes the network only within M hops of what the rebuild changed, the rest kept from
    the pass before (the same numbers up to float rounding, faster; false: whole passes;
    :mod:`physgnn.models.passes`); ``energy_guard``: outside training, a frame's contacts
    raise no contact group's energy beyond what parts its overlaps, plus ``energy_slack``
    metres of its weight (its contact changes scaled by one factor per group: momentum kept;
    :mod:`physgnn.models.energy_guard`); ``friction_cone``: outside training, the node
    decoder's own change along a plane that presses the sphere at most ``μ`` times the plane's
    push (Coulomb; :mod:`physgnn.models.friction`); ``rest_consistent``: outside training,
    the rest decision stops only spheres whose own answer moves along the ground slower than
    friction could stop in a frame (:func:`physgnn.models.rest.still_along_the_ground`)."""

    NODE: ClassVar[str] = "model.contacts"
    gravity_prior: bool = True
    contact_passes: int = ranged(whole(0, what="rebuilds; 0: one pass"), default=2)
    pair_impulses: bool = True
    rest_decision: bool = True
    rest_speed: float = ranged(number(0, above=True, what="m/s"), default=0.01)
    recent_contact: bool = False
    contact_memory: bool = False
    plane_floor: bool = True
    plane_newton: bool = True
    pair_floor: bool = False
    pair_newton: bool = False
    incremental_passes: bool = True
    energy_guard: bool = True
    energy_slack: float = ranged(number(0, what="m of the scene's weight"), default=0.0)
    friction_cone: bool = True
    rest_consistent: bool = True

    def __post_init__(self) -> None:
        check_fields(self)
