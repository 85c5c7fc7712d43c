"""Scenes as data: the YAML scene format, read and written.

A scene file says everything a :class:`~physgnn.physics.scene.Scene` holds (schema:
:mod:`physgnn.groundtruth.scene_schema`, ``docs/scene.schema.json``; README "Scene files")::

    name: throw
    dt: 0.1                 # frame interval (s)
    frames: 60
    effects: {rotation: true}           # omitted effects are on
    materials:
      rubber: {restitution: 0.8, lateral_friction: 0.5}
    spheres:
      - {radius: 0.5, density: 1000, material: rubber, position: [0, 0, 3],
         velocity: [4, 0, 2], angular_velocity: [0, 0, 1], orientation: [1, 0, 0, 0]}
    planes:                 # bounded rectangles; the ground z = 0 is always there
      - {kind: static, centre: [5, 0, 1], normal: [-0.5, 0, 0.87], reference: [0, 1, 0],
         half_lengths: [2, 3]}

Numbers are YAML 1.2's (``1e1``, ``1e+01`` and ``.5`` are floats, not strings as in YAML 1.1).
:func:`load_scene` fails with one line naming the file, the place and the problem (unknown
key, wrong type, overlapping spheres, a zero normal, a sphere inside a plane, ...).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import yaml

from physgnn import SCENES_DIR
from physgnn.files import write_text
from physgnn.groundtruth.layouts import check_above_ground, check_clear_of_planes, check_no_overlap
from physgnn.groundtruth.scene_schema import MATERIAL, PLANE, SCHEMA, SPHERE
from physgnn.groundtruth.scene_values import (
    coefficients,
    known_keys,
    number,
    restitution,
    unit,
    vector,
)
from physgnn.groundtruth.scene_yaml import SceneLoader
from physgnn.physics.scene import (
    GRAVITY,
    GROUND,
    PLANE_KINDS,
    PLANE_MATERIAL,
    Effects,
    Material,
    Scene,
    SceneError,
    as_float32,
    ground_plane,
)
from physgnn.ranges import whole

DEFAULT_MATERIAL = "default"
FRAMES = whole(2, what="frames to simulate, the first is the start")


def _materials(where: str, d) -> tuple[list[str], np.ndarray]:
    if d is None:
        return [DEFAULT_MATERIAL], Material().as_array()[None]
    if not isinstance(d, dict) or not d:
        raise SceneError(f"{where}: expected a non-empty mapping of name -> parameters")
    rows = []
    for name, m in d.items():
        w = f"{where}.{name}"
        rows.append(Material(**coefficients(w, known_keys(w, m or {}, MATERIAL))).as_array())
    return [str(k) for k in d], np.stack(rows)


def _sphere(where: str, d, names: list[str]) -> dict:
    d = known_keys(where, d, SPHERE)
    r = number(f"{where}.radius", d["radius"], positive=True)
    if "mass" in d and "density" in d:
        raise SceneError(f"{where}: give mass or density, not both")
    if "mass" in d:
        mass = number(f"{where}.mass", d["mass"], positive=True)
    else:
        mass = number(f"{where}.density", d.get("density", 1000.0), True) * 4 / 3 * np.pi * r**3
    material = d.get("material", names[0])
    if material not in names:
        raise SceneError(f"{where}.material: unknown material '{material}'; known: {names}")
    zero = [0.0, 0.0, 0.0]
    return dict(
        radius=r,
        mass=mass,
        material=names.index(material),
        pos=vector(f"{where}.position", d["position"], 3),
        quat=unit(f"{where}.orientation", d.get("orientation", [1.0, 0, 0, 0]), 4),
        vel=vector(f"{where}.velocity", d.get("velocity", zero), 3),
        angvel=vector(f"{where}.angular_velocity", d.get("angular_velocity", zero), 3),
    )


def _plane_materials(restitutions: list[float]) -> np.ndarray | None:
    """``[S, 4]`` plane materials of these restitutions (None when all are 1: the default)."""
    if all(e == 1.0 for e in restitutions):
        return None
    return np.array([[e, *PLANE_MATERIAL[1:]] for e in restitutions], dtype=np.float32)


def _plane(where: str, d) -> tuple[np.ndarray, int, float]:
    d = known_keys(where, d, PLANE)
    kind = d.get("kind", "static")
    if kind not in ("wall", "static"):
        raise SceneError(f"{where}.kind: expected 'wall' or 'static', got {kind!r}")
    n = unit(f"{where}.normal", d["normal"], 3)
    ref = unit(f"{where}.reference", d["reference"], 3)
    if abs(float(n @ ref)) > 1e-3:
        raise SceneError(
            f"{where}: reference {ref.round(3).tolist()} is not perpendicular to normal"
        )
    ref = ref - (n @ ref) * n
    half = vector(f"{where}.half_lengths", d["half_lengths"], 2)
    if np.any(half <= 0):
        raise SceneError(f"{where}.half_lengths: must be > 0, got {half.tolist()}")
    centre = vector(f"{where}.centre", d["centre"], 3)
    row = np.concatenate([centre, n, ref / np.linalg.norm(ref), half])
    e = restitution(f"{where}.restitution", d.get("restitution", 1.0))
    return row, PLANE_KINDS.index(kind), e


def check_placement(where: str, pos, radius, planes) -> None:
    """No two spheres overlap, none reaches below the ground or into a plane's solid (pos
    ``[N, 3]``, radius ``[N]``, planes ``[S, 11]``, row 0 the ground): a scene file's check,
    and :func:`physgnn.api.scene_from_arrays`'s; one line naming ``where`` and the sphere."""
    pos, radius = np.asarray(pos, np.float64), np.asarray(radius, np.float64)
    check_no_overlap(where, pos, radius)
    check_above_ground(where, pos, radius)
    try:
        check_clear_of_planes(where, pos, radius, np.asarray(planes, np.float64), depth=1.0)
    except SceneError as e:  # depth: the engine's solid behind a plane
        raise SceneError(str(e).replace(f"scene '{where}'", where)) from None


def _column(rows: list[dict], key: str) -> np.ndarray:
    """``key`` of every sphere row, stacked: ``[N, ·]``."""
    return np.stack([np.asarray(r[key]) for r in rows])


def scene_from_dict(d, where: str = "scene") -> Scene:
    """A validated :class:`Scene` from a parsed scene file; ``where`` prefixes errors."""
    d = known_keys(where, d, SCHEMA)
    names, materials = _materials(f"{where}: materials", d.get("materials"))
    spheres = d["spheres"]
    if not isinstance(spheres, list) or not spheres:
        raise SceneError(f"{where}: spheres must be a non-empty list")
    rows = [_sphere(f"{where}: spheres[{i}]", s, names) for i, s in enumerate(spheres)]
    planes = [_plane(f"{where}: planes[{i}]", p) for i, p in enumerate(d.get("planes") or [])]
    ground_e = restitution(f"{where}: ground_restitution", d.get("ground_restitution", 1.0))
    pos, radius = _column(rows, "pos"), _column(rows, "radius")
    plane_rows = np.stack([ground_plane().astype(np.float64), *[p for p, _, _ in planes]])
    check_placement(where, pos, radius, plane_rows)
    try:
        effects = Effects.from_dict(d.get("effects"))
    except (SceneError, TypeError) as e:
        raise SceneError(f"{where}: effects: {e}") from None
    scene = Scene(
        name=str(d.get("name", "scene")),
        radius=as_float32(radius),
        mass=as_float32(_column(rows, "mass")),
        material=_column(rows, "material").astype(np.int64),
        pos=as_float32(pos),
        quat=as_float32(_column(rows, "quat")),
        vel=as_float32(_column(rows, "vel")),
        angvel=as_float32(_column(rows, "angvel")),
        planes=as_float32(plane_rows),
        plane_kind=np.array([GROUND] + [k for _, k, _ in planes], dtype=np.int64),
        plane_materials=_plane_materials([ground_e] + [e for *_, e in planes]),
        materials=as_float32(materials),
        dt=number(f"{where}: dt", d.get("dt", 0.1), positive=True),
        n_frames=FRAMES.check(
            f"{where}: frames", d.get("frames", 100), "e.g. frames: 100", SceneError
        ),
        effects=effects,
        gravity=tuple(vector(f"{where}: gravity", d.get("gravity", list(GRAVITY)), 3)),
    )
    try:
        return scene.validate()
    except SceneError as e:
        raise SceneError(f"{where}: {e}") from None


def scene_file(path: str | Path) -> Path:
    """``path`` when it is a file, else the example scene of that name (``throw`` or
    ``throw.yaml``: ``conf/scene/throw.yaml``, which the installed package carries too)."""
    path = Path(path)
    if path.is_file():
        return path
    if path.is_dir():
        raise SceneError(f"scene file {path} is a folder; give a YAML scene file in it")
    example = Path(SCENES_DIR) / f"{path.stem}.yaml"
    if path.parent == Path(".") and example in example_scenes():
        return example
    names = ", ".join(p.stem for p in example_scenes())
    raise SceneError(f"scene file {path} does not exist; give a YAML file or an example ({names})")


def example_scenes() -> list[Path]:
    """The scene files of the ``scene`` config group (beside the scene families' configs)."""
    found = sorted(Path(SCENES_DIR).glob("*.yaml"))
    return [p for p in found if re.search(r"^spheres:", p.read_text(), re.MULTILINE)]


def load_scene(path: str | Path) -> Scene:
    """Read and check a YAML scene file (or an example scene's name, :func:`scene_file`);
    one-line :class:`SceneError` on any problem."""
    path = scene_file(path)
    try:
        d = yaml.load(path.read_text(), Loader=SceneLoader)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        at = f" (line {mark.line + 1})" if mark else ""
        raise SceneError(f"{path}: not valid YAML{at}: {getattr(e, 'problem', e)}") from None
    scene = scene_from_dict(d, where=str(path))
    if "name" not in d:
        scene.name = path.stem
    return scene


def _list(a) -> list:
    return [round(float(x), 7) for x in np.asarray(a).ravel()]


def _plane_restitutions(scene: Scene) -> np.ndarray | None:
    """``[S]`` restitutions of the scene's planes (None: the default planes); a scene file
    holds no other plane coefficient, so a plane of another friction is refused."""
    if scene.plane_materials is None:
        return None
    m = np.asarray(scene.plane_materials, dtype=np.float64)
    if not np.allclose(m[:, 1:], PLANE_MATERIAL[1:]):
        raise SceneError(f"scene '{scene.name}': a scene file holds a plane's restitution only")
    return m[:, 0]


def scene_to_dict(scene: Scene) -> dict:
    """The scene-file form of ``scene`` (the ground, row 0, is implicit)."""
    keys = ("restitution", "lateral_friction", "rolling_friction", "spinning_friction")
    mats = {f"m{k}": dict(zip(keys, _list(m), strict=True)) for k, m in enumerate(scene.materials)}
    spheres = [
        {
            "radius": float(round(float(scene.radius[i]), 7)),
            "mass": float(round(float(scene.mass[i]), 7)),
            "material": f"m{int(scene.material[i])}",
            "position": _list(scene.pos[i]),
            "orientation": _list(scene.quat[i]),
            "velocity": _list(scene.vel[i]),
            "angular_velocity": _list(scene.angvel[i]),
        }
        for i in range(scene.n_spheres)
    ]
    rest = _plane_restitutions(scene)
    planes = [
        {
            "kind": PLANE_KINDS[int(k)],
            "centre": _list(row[:3]),
            "normal": _list(row[3:6]),
            "reference": _list(row[6:9]),
            "half_lengths": _list(row[9:11]),
        }
        | ({} if rest is None else {"restitution": _list(rest[s])[0]})
        for s, (row, k) in enumerate(zip(scene.planes, scene.plane_kind, strict=True))
        if int(k) != GROUND
    ]
    ground = {} if rest is None else {"ground_restitution": _list(rest[:1])[0]}
    return ground | {
        "name": scene.name,
        "dt": float(scene.dt),
        "frames": int(scene.n_frames),
        "gravity": _list(scene.gravity),
        "effects": scene.effects.as_dict(),
        "materials": mats,
        "spheres": spheres,
        "planes": planes,
    }


class _Dumper(yaml.SafeDumper):
    """Vectors ``[x, y, z]`` on one line."""


def _represent_list(dumper, data):
    flow = all(not isinstance(x, dict | list) for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_Dumper.add_representer(list, _represent_list)


def write_scene(path: str | Path, scene: Scene) -> Path:
    """Write ``scene`` as a YAML scene file (vectors on one line)."""
    text = yaml.dump(scene_to_dict(scene), Dumper=_Dumper, sort_keys=False, width=100)
    return write_text(path, text)
