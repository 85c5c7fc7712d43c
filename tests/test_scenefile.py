"""The YAML scene format (physgnn.scenefile): round trips, examples, one-line errors."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import compose_generate

from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.layouts import check_no_overlap
from physgnn.groundtruth.scene_schema import SCHEMA
from physgnn.groundtruth.scenefile import (
    example_scenes,
    load_scene,
    scene_from_dict,
    scene_to_dict,
    write_scene,
)
from physgnn.physics.scene import SceneError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = example_scenes()  # the scene files among conf/scene/
ARRAYS = ("radius", "mass", "material", "pos", "quat", "vel", "angvel", "planes", "plane_kind")


def base() -> dict:
    return {
        "dt": 0.1,
        "frames": 5,
        "materials": {"a": {"restitution": 0.5}},
        "spheres": [{"radius": 0.5, "position": [0, 0, 1]}, {"radius": 0.5, "position": [2, 0, 1]}],
    }


@pytest.mark.parametrize("family", ["random_box", "ood_cubes_ramps", "ood_resting_hit"])
def test_builtin_scene_round_trips_through_a_file(family, tmp_path):
    cfg = compose_generate(["data=tiny"]).data
    c = cfg.scene if family == "random_box" else cfg.ood[family]
    scene = build_scene(c, np.random.default_rng(3))
    again = load_scene(write_scene(tmp_path / "s.yaml", scene))
    for key in ARRAYS:
        np.testing.assert_allclose(getattr(again, key), getattr(scene, key), rtol=1e-6, atol=1e-6)
    assert (again.dt, again.n_frames, again.effects) == (scene.dt, scene.n_frames, scene.effects)
    np.testing.assert_allclose(again.materials, scene.materials, atol=1e-6)


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_scenes_load(path):
    scene = load_scene(path)
    assert scene.n_spheres >= 2 and scene.name == path.stem


def test_defaults_and_density():
    scene = scene_from_dict(base())
    assert scene.planes.shape == (1, 11) and scene.plane_kind.tolist() == [0]
    np.testing.assert_allclose(scene.mass, 1000 * 4 / 3 * np.pi * 0.125, rtol=1e-6)
    np.testing.assert_array_equal(scene.quat, [[1, 0, 0, 0]] * 2)


def test_any_plane_orientation_is_kept():
    d = base()
    n = np.array([1.0, -2.0, 3.0]) / np.sqrt(14)
    d["planes"] = [
        {"centre": [0, 0, 5], "normal": [1, -2, 3], "reference": [2, 1, 0], "half_lengths": [2, 1]}
    ]
    row = scene_from_dict(d).planes[1]
    np.testing.assert_allclose(row[3:6], n, atol=1e-6)
    np.testing.assert_allclose(row[6:9], np.array([2, 1, 0]) / np.sqrt(5), atol=1e-6)


def _error(d) -> str:
    with pytest.raises(SceneError) as e:
        scene_from_dict(d, where="f.yaml")
    assert "\n" not in str(e.value)
    return str(e.value)


def test_unknown_keys_are_named():
    d = base()
    d["spheres"][1]["veloctiy"] = [1, 0, 0]
    assert "spheres[1]: unknown key 'veloctiy'" in _error(d)
    assert "unknown key 'frame'" in _error({**base(), "frame": 3})
    assert "materials.a: unknown key 'bounce'" in _error(
        {**base(), "materials": {"a": {"bounce": 1}}}
    )


def test_overlapping_spheres():
    d = base()
    d["spheres"][1]["position"] = [0.9, 0, 1]
    assert "spheres[0] and spheres[1] overlap by 0.1 m" in _error(d)


def grid() -> np.ndarray:
    """Centres ``[2000, 3]`` of touching unit spheres on the ground, ordered by x, y, z."""
    xyz = np.stack(np.meshgrid(np.arange(20), np.arange(10), np.arange(10), indexing="ij"), -1)
    return xyz.reshape(-1, 3) + [0, 0, 0.5]


def test_thousands_of_touching_spheres_load_and_an_overlap_is_named(tmp_path):
    spheres = [{"radius": 0.5, "position": p} for p in grid().tolist()]
    spheres.append({"radius": 2.8, "position": [-3.5, 5, 3.5]})  # a big one beside them
    path = tmp_path / "many.yaml"
    path.write_text(yaml.safe_dump({"spheres": spheres}))
    assert load_scene(path).n_spheres == 2001
    spheres[-1]["position"][0] = -3.25  # into spheres[53], at [0, 5, 3.5]
    assert _error({"spheres": spheres}) == "f.yaml: spheres[53] and spheres[2000] overlap by 0.05 m"
    spheres[-1]["position"][0] = -3.5
    spheres[1234]["position"][0] -= 0.25  # into spheres[1134], its neighbour along x
    assert "spheres[1134] and spheres[1234] overlap by 0.25 m" in _error({"spheres": spheres})


def test_the_overlap_check_holds_no_n_by_n_array():
    tracemalloc.start()
    check_no_overlap("f.yaml", grid(), np.full(2000, 0.5))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 2000 * 2000  # bytes; an [N, N] float array is 8 times that


def test_zero_normal():
    d = base()
    d["planes"] = [
        {"centre": [0, 0, 5], "normal": [0, 0, 0], "reference": [1, 0, 0], "half_lengths": [2, 1]}
    ]
    assert "planes[0].normal: has length 0" in _error(d)


def test_sphere_inside_a_plane():
    d = base()
    d["planes"] = [
        {"centre": [0, 0, 1.2], "normal": [0, 0, 1], "reference": [1, 0, 0], "half_lengths": [2, 1]}
    ]
    assert "sphere 0" in _error(d) and "inside a plane" in _error(d)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"radius": -1}, "spheres[0].radius: must be > 0"),
        ({"position": [0, 0]}, "spheres[0].position: expected a list of 3 numbers"),
        ({"mass": 1, "density": 2}, "give mass or density, not both"),
        ({"material": "steel"}, "unknown material 'steel'"),
        ({"velocity": [0, "x", 0]}, "spheres[0].velocity: expected a number"),
        ({"position": [0, 0, 0.2]}, "below the ground"),
    ],
)
def test_bad_sphere_fields(change, message):
    d = base()
    d["spheres"][0].update(change)
    assert message in _error(d)


def test_file_errors(tmp_path):
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("spheres: [\n  {radius: 1,\n")
    with pytest.raises(SceneError, match="not valid YAML"):
        load_scene(bad)
    bad.write_text(yaml.safe_dump({"spheres": []}))
    with pytest.raises(SceneError, match="non-empty list"):
        load_scene(bad)


NUMBERS = """
dt: 1e-1
frames: 1e1
spheres:
  - {radius: .5, density: 1E3, position: [0, 0, 1e+01]}
  - {radius: 5e-1, mass: 1_000, position: [-2, +1.5E0, 1.0e1], velocity: [1.5E-3, 0, -.5e1]}
"""


def test_numbers_are_read_however_they_are_written(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(NUMBERS)
    scene = load_scene(path)
    assert (scene.dt, scene.n_frames) == (np.float32(0.1), 10)
    np.testing.assert_array_equal(scene.radius, [0.5, 0.5])
    np.testing.assert_allclose(scene.mass, [1000 * 4 / 3 * np.pi * 0.125, 1000], rtol=1e-6)
    np.testing.assert_array_equal(scene.pos, [[0, 0, 10], [-2, 1.5, 10]])
    np.testing.assert_allclose(scene.vel[1], [1.5e-3, 0, -5], rtol=1e-6)


@pytest.mark.parametrize("value", ["1e", "e1", "1e+", "1.5.2", "ten", "'1e1'"])
def test_what_is_not_a_number_is_still_one_line(value, tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(f"spheres:\n  - {{radius: 0.5, position: [0, 0, {value}]}}\n")
    with pytest.raises(SceneError) as e:
        load_scene(path)
    got = repr(value.strip("'"))
    assert str(e.value) == f"{path}: spheres[0].position: expected a number, got {got}"


def test_committed_schema_is_current():
    committed = json.loads((ROOT / "docs" / "scene.schema.json").read_text())
    assert committed == json.loads(json.dumps(SCHEMA))


def test_exported_dict_uses_only_schema_keys():
    d = scene_to_dict(scene_from_dict(base()))
    assert set(d) <= set(SCHEMA["properties"])


def test_generate_exports_scene_files(tmp_path):
    from physgnn.groundtruth.generate import generate

    cfg = compose_generate(["data=tiny", f"paths.outputs={tmp_path}", f"export_scene={tmp_path}/s"])
    folder = generate(cfg)
    names = sorted(p.name for p in folder.glob("*.yaml"))
    assert "train_traj_00000.yaml" in names and "ood_ood_cubes_ramps.yaml" in names
    assert len(names) == 2 + 1 + 1 + 4
    assert load_scene(folder / "ood_ood_cubes_ramps.yaml").planes.shape[0] == 7
    assert not (tmp_path / "data").exists()
