"""JSON schema of the YAML scene format (:mod:`physgnn.groundtruth.scenefile`).

``python -m physgnn.groundtruth.scene_schema > docs/scene.schema.json`` writes it (the
committed copy is checked against this one by the tests).
:mod:`physgnn.groundtruth.scenefile` checks files itself, with one-line errors; the schema is
for editors and other tools.
"""

from __future__ import annotations

import json

from physgnn.physics.scene import EFFECT_NAMES, GRAVITY, MAX_FRAMES

_VEC3 = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}
_QUAT = {
    "type": "array",
    "items": {"type": "number"},
    "minItems": 4,
    "maxItems": 4,
    "description": "unit quaternion (w, x, y, z); normalised on load",
}
_POS = {"type": "number", "exclusiveMinimum": 0}
_RESTITUTION = {"type": "number", "minimum": 0, "maximum": 1, "default": 1}

MATERIAL = {
    "type": "object",
    "additionalProperties": False,
    "properties": {
        "restitution": {"type": "number", "minimum": 0, "maximum": 1},
        "lateral_friction": {"type": "number", "minimum": 0},
        "rolling_friction": {"type": "number", "minimum": 0},
        "spinning_friction": {"type": "number", "minimum": 0},
    },
}

SPHERE = {
    "type": "object",
    "additionalProperties": False,
    "required": ["radius", "position"],
    "properties": {
        "radius": _POS,
        "mass": {**_POS, "description": "kg; give mass or density, not both"},
        "density": {**_POS, "description": "kg/m³ (default 1000): mass = density·4/3·π·r³"},
        "material": {"type": "string", "description": "a key of materials (default: the first)"},
        "position": _VEC3,
        "orientation": _QUAT,
        "velocity": _VEC3,
        "angular_velocity": {**_VEC3, "description": "rad/s, world frame"},
    },
}

PLANE = {
    "type": "object",
    "additionalProperties": False,
    "required": ["centre", "normal", "reference", "half_lengths"],
    "properties": {
        "kind": {"enum": ["wall", "static"], "default": "static"},
        "centre": _VEC3,
        "normal": {**_VEC3, "description": "the solid side is behind it; normalised on load"},
        "reference": {**_VEC3, "description": "in-plane direction d, perpendicular to normal"},
        "half_lengths": {
            "type": "array",
            "items": _POS,
            "minItems": 2,
            "maxItems": 2,
            "description": "half lengths along reference and along normal × reference (m)",
        },
        "restitution": {**_RESTITUTION, "description": "a sphere of e bounces off it with e·this"},
    },
}

SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "physgnn scene",
    "type": "object",
    "additionalProperties": False,
    "required": ["spheres"],
    "properties": {
        "name": {"type": "string"},
        "dt": {**_POS, "default": 0.1, "description": "frame interval (s)"},
        "frames": {"type": "integer", "minimum": 2, "maximum": MAX_FRAMES, "default": 100},
        "gravity": {**_VEC3, "default": list(GRAVITY)},
        "effects": {
            "type": "object",
            "additionalProperties": False,
            "properties": {name: {"type": "boolean"} for name in EFFECT_NAMES},
        },
        "materials": {"type": "object", "additionalProperties": MATERIAL},
        "spheres": {"type": "array", "items": SPHERE, "minItems": 1},
        "planes": {"type": "array", "items": PLANE},
        "ground_restitution": {**_RESTITUTION, "description": "the ground's, as a plane's"},
    },
}


if __name__ == "__main__":
    print(json.dumps(SCHEMA, indent=2, ensure_ascii=False))
