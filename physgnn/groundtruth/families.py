"""Scene families built from a config (Hydra group ``scene/``) and a numpy ``Generator``.

``build_scene(cfg, rng)`` dispatches on ``cfg.name``. Every config has ``dt``, ``n_frames``,
``effects`` (dict of :data:`physgnn.physics.scene.EFFECT_NAMES`), ``materials`` (list of dicts of
:class:`physgnn.physics.scene.Material` fields) or ``material_ranges`` and
``materials_per_scene`` (drawn materials), optionally ``plane_restitution`` (drawn per scene;
:mod:`physgnn.groundtruth.assemble`) and ``density`` (kg/m³, mass = density·4/3·π·r³).
Arenas are squares of side ``side`` centred at the origin, closed by 4 walls of height
``wall_height`` (planes of kind wall, normals inward); the ground is always plane row 0.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
from omegaconf import DictConfig

from physgnn.groundtruth.assemble import finish_scene, plain_config
from physgnn.groundtruth.layouts import (
    aggregate_positions,
    arena_planes,
    check_clear_of_planes,
    clustered_positions,
    cube_positions,
    ground_only,
    pile_positions,
    ramp_plane,
    row_positions,
    spawn_without_overlap,
)
from physgnn.groundtruth.resting import ball_vectors, rest_layout
from physgnn.groundtruth.scenefile import scene_from_dict
from physgnn.physics.scene import STATIC, Scene, SceneError
from physgnn.ranges import number, whole


def _contact_scene(c: dict, rng: np.random.Generator) -> Scene | None:
    """A dense scene with probability ``dense_fraction``, a rest scene with ``rest_fraction``,
    else None (one draw; none when both are 0, so that such scenes stay as they were)."""
    dense, rest = c.get("dense_fraction", 0.0), c.get("rest_fraction", 0.0)
    if dense <= 0 and rest <= 0:
        return None
    u = rng.uniform()
    if u < dense:
        return dense_contact(c, rng)
    return resting_contact(c, rng) if u < dense + rest else None


def _box_size(c: dict, rng: np.random.Generator) -> tuple[int, float, float]:
    """``(N, arena side, highest centre)`` of a random_box scene (a pile scene or not)."""
    # The extra draw only when piles are asked for: scenes without them stay as they were.
    if c.get("pile_fraction", 0.0) > 0 and rng.uniform() < c["pile_fraction"]:
        n = int(rng.integers((c["n_max"] + 1) // 2, c["n_max"] + 1))
        side = float(rng.uniform(c["pile_side_min"], c["pile_side_max"]))
        return n, side, float(c["pile_h_max"])
    n = int(rng.integers(c["n_min"], c["n_max"] + 1))
    return n, float(rng.uniform(c["side_min"], c["side_max"])), float(c["h_max"])


def random_box(c: dict, rng: np.random.Generator) -> Scene:
    """N ~ U{n_min..n_max} spheres of radius U[radius_min, radius_max] at heights in
    (r, h_max] over a square arena of side U[side_min, side_max] with 4 walls. Initial
    horizontal velocities are uniform in a disc of radius ``max_speed0`` and angular
    velocities uniform in a ball of radius ``max_angvel0`` (more rolling and wall hits).
    With probability ``cluster_fraction`` (default 0) the spheres start as one block of close
    spheres (:func:`clustered_positions`) instead of scattered: many neighbours falling and
    landing together. With probability ``pile_fraction`` (default 0) the scene is a *pile*
    scene: N ~ U{⌈n_max/2⌉..n_max} spheres scattered (no lattice) over a small arena of side
    U[pile_side_min, pile_side_max], up to ``pile_h_max``, so that they settle into touching
    groups and piles that then rest. With probability ``dense_fraction`` (default 0) it is a
    *dense* scene instead (:func:`dense_contact`), with ``rest_fraction`` (default 0) a *rest*
    scene (:func:`resting_contact`)."""
    if c["n_min"] < 1 or c["n_max"] < c["n_min"]:
        raise SceneError(
            f"random_box: need 1 <= n_min <= n_max (got {c['n_min']}, {c['n_max']}): "
            "a scene needs at least one sphere"
        )
    if c["radius_min"] <= 0 or c["radius_max"] < c["radius_min"]:
        raise SceneError(
            f"random_box: need 0 < radius_min <= radius_max "
            f"(got {c['radius_min']}, {c['radius_max']})"
        )
    # The extra draw only when dense scenes are asked for: scenes without them stay as they were.
    contact = _contact_scene(c, rng)
    if contact is not None:
        return contact
    n, side, h_max = _box_size(c, rng)
    radius = rng.uniform(c["radius_min"], c["radius_max"], size=n)
    half = side / 2
    pos = None
    # The extra draw only when clusters are asked for: scenes without them stay as they were.
    if c.get("cluster_fraction", 0.0) > 0 and rng.uniform() < c["cluster_fraction"]:
        pos = clustered_positions(rng, radius, half, h_max, c.get("cluster_max_gap", 0.5))
    if pos is None:
        pos = spawn_without_overlap(
            rng,
            radius,
            np.array([-half, -half, 0.0]),
            np.array([half, half, h_max]),
            int(c["spawn_tries"]),
        )
    ang = rng.uniform(0, 2 * np.pi, size=n)
    speed = c["max_speed0"] * np.sqrt(rng.uniform(size=n))
    vel = np.stack([speed * np.cos(ang), speed * np.sin(ang), np.zeros(n)], axis=1)
    w = ball_vectors(rng, n, c["max_angvel0"])
    planes, kinds = arena_planes(side, c["wall_height"])
    return finish_scene(c, pos, radius, rng, planes, kinds, vel=vel, angvel=w)


DENSE_KINDS = ("flying_aggregate", "settling_aggregate", "sliding_row")


def dense_contact(c: dict, rng: np.random.Generator) -> Scene:
    """A dense-contact scene of the training mix: N ~ U{⌈n_max/2⌉..n_max} spheres, touching or
    nearly touching (gaps 0 or U(0, ``dense_max_gap``)), in an arena of the usual side; one of
    :data:`DENSE_KINDS` with equal odds:

    - ``flying_aggregate``: a random aggregate (:func:`aggregate_positions`, no lattice) high
      in the air, all spheres with one common velocity (horizontal in a disc of ``max_speed0``,
      vertical U[−2, 4] m/s) and no spin: a group that flies as one, then lands;
    - ``settling_aggregate``: the same aggregate at rest on the ground, which collapses into a
      pile and rests;
    - ``sliding_row``: a row on the ground (:func:`row_positions`) with one common horizontal
      velocity of speed U[0.5, max_speed0] in a random direction: touching spheres that move
      together.

    Spheres beyond the arena's walls are left out (at least one stays)."""
    n = int(rng.integers((c["n_max"] + 1) // 2, c["n_max"] + 1))
    radius = rng.uniform(c["radius_min"], c["radius_max"], size=n)
    half = float(rng.uniform(c["side_min"], c["side_max"])) / 2
    kind = DENSE_KINDS[int(rng.integers(len(DENSE_KINDS)))]
    gap = float(c.get("dense_max_gap", 0.1))
    vel = np.zeros((n, 3))
    if kind == "sliding_row":
        pos = row_positions(rng, radius, gap)
        a, speed = rng.uniform(0, 2 * np.pi), rng.uniform(0.5, max(0.5, c["max_speed0"]))
        vel[:] = [speed * np.cos(a), speed * np.sin(a), 0.0]
    else:
        pos = aggregate_positions(rng, radius, gap)
        pos[:, :2] -= pos[:, :2].mean(0)
    if kind == "flying_aggregate":
        top = max(float(pos[:, 2].max()), 1.0)
        pos[:, 2] += rng.uniform(1.0, max(1.0, c["h_max"] - top))
        a, speed = rng.uniform(0, 2 * np.pi), c["max_speed0"] * np.sqrt(rng.uniform())
        vel[:] = [speed * np.cos(a), speed * np.sin(a), rng.uniform(-2.0, 4.0)]
    room = half - radius[:, None] - 0.05
    shift = rng.uniform(-1, 1, size=2) * max(0.0, float((room - np.abs(pos[:, :2])).min()))
    pos[:, :2] += shift
    inside = np.all(np.abs(pos[:, :2]) <= room, axis=1)
    inside[np.argmin(np.abs(pos[:, :2]).max(1))] = True
    planes, kinds = arena_planes(2 * half, c["wall_height"])
    return finish_scene(c, pos[inside], radius[inside], rng, planes, kinds, vel=vel[inside])


def resting_contact(c: dict, rng: np.random.Generator) -> Scene:
    """A rest scene of the training mix: N ~ U{⌈n_max/2⌉..n_max} spheres resting on each other
    and the ground (:func:`~physgnn.groundtruth.resting.rest_layout`: columns, a pyramid,
    hexagonal layers or a deposit, equal odds; gaps 0 or U(0, ``rest_max_gap``)) at a random
    place of an arena of the usual side (or just wider than the layout). With probability
    ``rest_nudge_fraction`` every sphere starts with a velocity uniform in a ball of radius
    ``rest_nudge_speed`` (m/s): a nudge that some of them do not survive."""
    n = int(rng.integers((c["n_max"] + 1) // 2, c["n_max"] + 1))
    pos, radius = rest_layout(rng, n, c["radius_min"], c["radius_max"], c["rest_max_gap"])
    extent = float(np.max(np.abs(pos[:, :2]) + radius[:, None])) + 0.05
    half = max(float(rng.uniform(c["side_min"], c["side_max"])) / 2, extent)
    pos[:, :2] += rng.uniform(extent - half, half - extent, size=2)
    vel = np.zeros_like(pos)
    if rng.uniform() < c["rest_nudge_fraction"]:
        vel = ball_vectors(rng, len(pos), c["rest_nudge_speed"])
    planes, kinds = arena_planes(2 * half, c["wall_height"])
    return finish_scene(c, pos, radius, rng, planes, kinds, vel=vel)


def _cubes(c: dict) -> np.ndarray:
    k, r, gap = int(c["k"]), float(c["radius"]), float(c["gap"])
    if k < 1:
        raise SceneError(f"{c['name']}: k must be >= 1 (got {k})")
    return np.concatenate([cube_positions(x, k, r, gap) for x in c["cube_corners"]])


def _arena(c: dict):
    return arena_planes(c["side"], c["wall_height"]) if c.get("walls", True) else ground_only()


def ood_cubes(c: dict, rng: np.random.Generator) -> Scene:
    """(a) 4 cubes of k×k×k spheres, ``gap`` apart, falling from ``cube_corners``."""
    planes, kinds = _arena(c)
    return finish_scene(c, _cubes(c), c["radius"], rng, planes, kinds)


def ood_cubes_ramps(c: dict, rng: np.random.Generator) -> Scene:
    """(b) (a) plus bounded inclined planes in the air (kind static), from ``ramps``: a list
    of ``{centre, slope_deg, half_length, half_width}`` descending towards +x."""
    planes, kinds = _arena(c)
    ramps = [
        ramp_plane(q["centre"], q["slope_deg"], q["half_length"], q["half_width"])
        for q in c["ramps"]
    ]
    planes = np.concatenate([planes, np.stack(ramps)])
    kinds = np.concatenate([kinds, np.full(len(ramps), STATIC)])
    pos = _cubes(c)
    check_clear_of_planes(c["name"], pos, c["radius"], planes.astype(np.float64))
    return finish_scene(c, pos, c["radius"], rng, planes, kinds)


def ood_resting_hit(c: dict, rng: np.random.Generator) -> Scene:
    """(c) Groups of touching spheres resting on the ground (rows of ``group_size`` along x
    starting at each ``group_starts``), a lone target sphere before each group, and a sphere
    dropped from each of ``drop_heights`` just off the target's centre (by ``drop_offset``
    along −x) so it glances off it and sends it rolling (+x) into its group."""
    r = float(c["radius"])
    pos = []
    for start in c["group_starts"]:
        for j in range(int(c["group_size"])):
            pos.append([start[0] + 2 * r * j, start[1], r])
    for target, h in zip(c["targets"], c["drop_heights"], strict=True):
        pos.append([target[0], target[1], r])
        pos.append([target[0] - c["drop_offset"], target[1], h])
    planes, kinds = _arena(c)
    return finish_scene(c, pos, r, rng, planes, kinds)


def ood_spaced_drop(c: dict, rng: np.random.Generator) -> Scene:
    """(d) A ``grid``×``grid`` layer of spheres ``spacing`` apart (centre to centre), all at
    ``height``, dropped from rest: they bounce without touching each other."""
    g, r, s = int(c["grid"]), float(c["radius"]), float(c["spacing"])
    if s <= 2 * r:
        raise SceneError(f"ood_spaced_drop: spacing {s} must exceed the diameter {2 * r}")
    xy = (np.arange(g) - (g - 1) / 2) * s
    gx, gy = np.meshgrid(xy, xy, indexing="ij")
    pos = np.stack([gx.ravel(), gy.ravel(), np.full(g * g, float(c["height"]))], axis=1)
    planes, kinds = _arena(c)
    return finish_scene(c, pos, r, rng, planes, kinds)


def resting_pile(c: dict, rng: np.random.Generator) -> Scene:
    """A pile of touching spheres at rest on the ground (:func:`pile_positions` with ``n``,
    ``layers``, ``radius``): nothing should move."""
    n, layers, r = int(c["n"]), int(c["layers"]), float(c["radius"])
    if n < 1 or not 1 <= layers <= n:
        raise SceneError(f"resting_pile: need n >= 1 and 1 <= layers <= n (got {n}, {layers})")
    planes, kinds = _arena(c)
    return finish_scene(c, pile_positions(n, layers, r), r, rng, planes, kinds)


BUILDERS: dict[str, Callable[[dict, np.random.Generator], Scene]] = {
    "random_box": random_box,
    "ood_cubes": ood_cubes,
    "ood_cubes_ramps": ood_cubes_ramps,
    "ood_resting_hit": ood_resting_hit,
    "ood_spaced_drop": ood_spaced_drop,
    # hard scenes of the stability suite (conf/scene/{resting_pile,drop_1000,tight_pack}.yaml)
    "resting_pile": resting_pile,
    "drop_1000": ood_spaced_drop,
    "tight_pack": ood_cubes,
}


def build_scene(cfg: Mapping | DictConfig, rng: np.random.Generator) -> Scene:
    """Build the scene family ``cfg.name`` with random draws from ``rng``; a scene file's
    content (``spheres``: ``conf/scene/throw.yaml``) is its one scene."""
    c = plain_config(cfg)
    if "spheres" in c:
        return scene_from_dict(c, where=f"scene '{c.get('name', 'scene')}'")
    name = c.get("name")
    if name not in BUILDERS:
        raise SceneError(f"unknown scene '{name}'; known: {', '.join(BUILDERS)}")
    try:
        return BUILDERS[name](c, rng)
    except KeyError as e:
        raise SceneError(f"scene '{name}': missing config key {e}") from None


# A trajectory's clock, checked naming its key (the scene's own check names none)
CLOCK = {
    "dt": number(0, above=True, what="s per frame", example=0.1),
    "n_frames": whole(2, what="frames of a trajectory: the first is the start", example=300),
}


def check_clock(data: Mapping | DictConfig) -> None:
    """``dt`` and ``n_frames`` of each scene of the preset ``data`` (``data.scene``,
    ``data.fit_scene``, ``data.ood.<name>``) in :data:`CLOCK`, else one line naming the key."""
    scenes = {"data.scene": data.get("scene"), "data.fit_scene": data.get("fit_scene")}
    scenes |= {f"data.ood.{name}": scene for name, scene in (data.get("ood") or {}).items()}
    for where, scene in scenes.items():
        for key, allowed in CLOCK.items():
            if scene is not None and key in scene:
                allowed.check(f"{where}.{key}", scene[key])
