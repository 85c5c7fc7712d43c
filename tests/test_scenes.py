"""Scene families (physgnn.groundtruth.families) built from the conf/scene configs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from truthkit import scene_cfg

from physgnn import CONF_DIR
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import BUILDERS, build_scene
from physgnn.physics.scene import GROUND, STATIC, WALL, SceneError

SCENE_DIR = Path(CONF_DIR) / "scene"


def pair_gaps(pos: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Surface-to-surface gaps of all pairs i < j, ``[P]``."""
    i, j = np.triu_indices(len(pos), 1)
    return np.linalg.norm(pos[i] - pos[j], axis=1) - radius[i] - radius[j]


@pytest.mark.parametrize("name", sorted(BUILDERS))
def test_every_config_builds_a_valid_scene_with_declared_effects(name):
    cfg = scene_cfg(name)
    scene = build_scene(cfg, np.random.default_rng(0))
    assert scene.name == name
    assert scene.effects.as_dict() == cfg["effects"]
    assert scene.plane_kind[0] == GROUND and np.all(scene.planes[0, :3] == 0)
    drawn = cfg.get("material_ranges") is not None
    assert len(scene.materials) == (cfg["materials_per_scene"] if drawn else len(cfg["materials"]))
    np.testing.assert_allclose(np.linalg.norm(scene.quat, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(scene.mass, 1000.0 * 4 / 3 * np.pi * scene.radius**3, rtol=1e-5)


def test_random_box_spawns_without_overlap_inside_the_arena():
    cfg = scene_cfg("random_box", n_min=20, n_max=20, side_min=6.0, side_max=6.0, h_max=8.0)
    for seed in range(10):
        s = build_scene(cfg, np.random.default_rng(seed))
        assert s.n_spheres == 20
        assert pair_gaps(s.pos, s.radius).min() > 0
        half = s.planes[1:, :2].max()  # walls at ±side/2
        assert half == pytest.approx(3.0)
        assert np.all(np.abs(s.pos[:, :2]) + s.radius[:, None] <= half + 1e-5)
        assert np.all(s.pos[:, 2] > s.radius) and np.all(s.pos[:, 2] <= 8.0)
        assert np.all(np.abs(s.vel[:, 2]) == 0)
        assert np.all(np.linalg.norm(s.vel, axis=1) <= cfg["max_speed0"] + 1e-6)
        assert list(s.plane_kind) == [GROUND, WALL, WALL, WALL, WALL]


def test_random_box_clusters_are_close_but_never_overlap():
    cfg = scene_cfg(
        "random_box",
        n_min=20,
        n_max=20,
        side_min=12.0,
        side_max=12.0,
        h_max=12.0,
        cluster_fraction=1.0,
        cluster_max_gap=0.2,
    )
    for seed in range(10):
        s = build_scene(cfg, np.random.default_rng(seed))
        gaps = pair_gaps(s.pos, s.radius)
        # lattice step = 2 r_max + U[0.01, 0.2]: nearest gaps are small, none negative
        assert gaps.min() > 0 and np.sort(gaps)[:20].max() < 1.2
        assert np.all(np.abs(s.pos[:, :2]) + s.radius[:, None] <= 6.0 + 1e-5)
        assert np.all(s.pos[:, 2] >= s.radius - 1e-6) and np.all(s.pos[:, 2] <= 12.0 + 1e-6)


def test_random_box_without_clusters_draws_as_before():
    plain = build_scene(scene_cfg("random_box"), np.random.default_rng(3))
    off = build_scene(scene_cfg("random_box", cluster_fraction=0.0), np.random.default_rng(3))
    assert np.array_equal(plain.pos, off.pos)


def test_walls_face_inwards():
    s = build_scene(scene_cfg("random_box"), np.random.default_rng(1))
    centres, normals = s.planes[1:, :3], s.planes[1:, 3:6]
    assert np.all((normals * -centres).sum(1) > 0)  # normal points towards the origin


def test_impossible_spawn_is_one_line():
    cfg = scene_cfg(
        "random_box", n_min=50, n_max=50, side_min=3.0, side_max=3.0, h_max=2.0, spawn_tries=50
    )
    with pytest.raises(SceneError, match="without overlap") as e:
        build_scene(cfg, np.random.default_rng(0))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("name", "overrides", "match"),
    [
        ("nope", {}, "unknown scene 'nope'; known: random_box, ood_cubes"),
        ("random_box", {"n_min": 0}, "at least one sphere"),
        ("random_box", {"radius_min": -0.5}, "radius_min"),
        ("ood_cubes", {"radius": -0.5}, "radius must be > 0"),
        ("ood_spaced_drop", {"spacing": 0.5}, "must exceed the diameter"),
        ("random_box", {"material_ranges": None, "materials": []}, "at least one material"),
        ("ood_cubes", {"effects": {"gravity": True, "magnetism": True}}, "unknown effect"),
    ],
)
def test_bad_scene_configs_are_one_line(name, overrides, match):
    cfg = scene_cfg("random_box") if name == "nope" else scene_cfg(name)
    cfg.update(overrides, name=name)
    with pytest.raises(SceneError, match=match) as e:
        build_scene(cfg, np.random.default_rng(0))
    assert "\n" not in str(e.value)


def test_missing_key_is_one_line():
    cfg = scene_cfg("ood_cubes")
    del cfg["k"]
    with pytest.raises(SceneError, match="missing config key 'k'"):
        build_scene(cfg, np.random.default_rng(0))


def test_ood_cubes_are_close_but_not_touching():
    cfg = scene_cfg("ood_cubes", k=3)
    s = build_scene(cfg, np.random.default_rng(0))
    assert s.n_spheres == 4 * 27
    gaps = pair_gaps(s.pos, s.radius)
    assert gaps.min() == pytest.approx(cfg["gap"], abs=1e-5)
    assert gaps.min() > 0


def test_ood_cubes_ramps_has_a_steep_and_a_slight_static_plane():
    s = build_scene(scene_cfg("ood_cubes_ramps"), np.random.default_rng(0))
    static = s.planes[s.plane_kind == STATIC]
    slopes = np.degrees(np.arccos(static[:, 5]))  # angle between normal and z
    np.testing.assert_allclose(sorted(slopes), [10.0, 40.0], atol=1e-3)
    assert np.all(static[:, 2] > 0)  # in the air


def test_ood_spaced_drop_spheres_never_touch_in_simulation():
    cfg = scene_cfg("ood_spaced_drop", grid=3, n_frames=60)
    traj = simulate(build_scene(cfg, np.random.default_rng(0)))
    gaps = np.stack([pair_gaps(p, traj.radius) for p in traj.pos])
    assert gaps.min() > 1.0
    assert np.all(np.diff(np.sign(traj.vel[:, :, 2]), axis=0).max(0) > 0)  # each one bounced


def test_ood_resting_hit_drops_hit_the_targets_which_hit_the_groups():
    cfg = scene_cfg("ood_resting_hit", n_frames=100)
    s = build_scene(cfg, np.random.default_rng(0))
    n_group = 2 * cfg["group_size"]
    assert pair_gaps(s.pos[:n_group], s.radius[:n_group]).min() == pytest.approx(0, abs=1e-5)
    assert np.all(s.pos[:n_group, 2] == pytest.approx(cfg["radius"]))
    assert s.pos[:, 2].max() == pytest.approx(230.0)
    traj = simulate(s)
    speed = np.linalg.norm(traj.vel, axis=-1)
    assert speed[:40, :n_group].max() < 1e-3  # the groups rest until hit
    assert np.all(speed[:, :n_group].max(0) > 0.5)  # every group sphere is set moving
    targets = [n_group, n_group + 2]
    assert np.all(speed[:, targets].max(0) > 2.0)


def test_cubes_spawned_inside_a_ramp_are_rejected():
    cfg = scene_cfg("ood_cubes_ramps")
    cfg["cube_corners"] = [[-10.0, -8.0, 9.0], *cfg["cube_corners"][1:]]  # below the steep ramp
    with pytest.raises(SceneError, match="starts on or inside a plane"):
        build_scene(cfg, np.random.default_rng(0))
