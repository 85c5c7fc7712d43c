"""The training mix's drawn materials and rest scenes (physgnn.groundtruth.assemble, resting,
families.resting_contact): what they say they make, checked by hand on the layouts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import compose_generate
from truthkit import family

from physgnn import CONF_DIR
from physgnn.groundtruth import resting
from physgnn.groundtruth.assemble import draw_materials, draw_plane_materials
from physgnn.groundtruth.families import build_scene, resting_contact
from physgnn.groundtruth.jobs import plan
from physgnn.groundtruth.layouts import cube_positions
from physgnn.physics.scene import SceneError

CONF = Path(CONF_DIR)
GAP = 0.01


def bonds(pos: np.ndarray, radius: np.ndarray, max_gap: float):
    """``(i, j, gap)`` of every pair i != j whose surfaces are at most ``max_gap`` apart."""
    i, j = np.nonzero(~np.eye(len(pos), dtype=bool))
    gap = np.linalg.norm(pos[i] - pos[j], axis=1) - radius[i] - radius[j]
    near = gap <= max_gap + 1e-9
    return i[near], j[near], gap[near]


def support_angles(pos, radius, max_gap) -> np.ndarray:
    """Degrees from vertical of the bonds from each sphere down to a sphere below it."""
    i, j, _ = bonds(pos, radius, max_gap)
    d = pos[i] - pos[j]
    up = d[:, 2] > 1e-9
    return np.degrees(np.arccos(d[up, 2] / np.linalg.norm(d[up], axis=1)))


def has_cubic_corner(pos, radius, max_gap, tol=0.05) -> bool:
    """A sphere with three touching neighbours along mutually perpendicular directions: every
    sphere of a simple cubic block of 2×2×2 or more (tight_pack) is one."""
    i, j, _ = bonds(pos, radius, max_gap)
    for s in np.unique(i):
        u = pos[j[i == s]] - pos[s]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        perp = np.abs(u @ u.T) < tol
        for a in range(len(u)):
            for b in np.flatnonzero(perp[a]):
                if np.any(perp[a] & perp[b]):
                    return True
    return False


def layouts(kind: str, seeds=range(12), n=20, max_gap=GAP):
    for seed in seeds:
        rng = np.random.default_rng(seed)
        if kind in ("column", "deposit"):
            fn = resting.column_positions if kind == "column" else resting.deposit_positions
            yield fn(rng, n, 0.5, 1.0, max_gap)
        else:
            fn = resting.pyramid_positions if kind == "pyramid" else resting.hex_layer_positions
            pos = fn(rng, n, 0.7, max_gap)
            yield pos, np.full(len(pos), 0.7)


@pytest.mark.parametrize("kind", resting.REST_KINDS)
def test_rest_layouts_touch_within_the_gap_without_overlap_and_rest_on_support(kind):
    for pos, radius in layouts(kind):
        assert len(pos) <= 20
        i, j, gap = bonds(pos, radius, GAP)
        every = np.linalg.norm(pos[:, None] - pos[None], axis=2) - radius[:, None] - radius
        assert every[~np.eye(len(pos), dtype=bool)].min() >= -1e-9  # no overlap at spawn
        assert np.all(pos[:, 2] >= radius - 1e-9)  # none below the ground
        on_ground = np.isclose(pos[:, 2], radius, atol=1e-9)
        below = np.zeros(len(pos), dtype=bool)
        below[i[pos[i, 2] > pos[j, 2] + 1e-9]] = True  # touches (within GAP) one below it
        assert np.all(on_ground | below), kind
        assert np.all(gap >= -1e-9) and np.all(gap <= GAP + 1e-9)


def test_columns_stand_straight_and_never_touch_each_other():
    for pos, radius in layouts("column"):
        axes = np.unique(pos[:, :2].round(9), axis=0)
        assert 1 <= len(axes) <= 10
        for a in axes:
            col = np.flatnonzero(np.all(np.isclose(pos[:, :2], a), axis=1))
            assert len(col) >= 2
        np.testing.assert_allclose(support_angles(pos, radius, GAP), 0.0, atol=1e-6)
        i, j, _ = bonds(pos, radius, resting.COLUMN_CLEARANCE - 1e-3)
        assert np.allclose(pos[i, :2], pos[j, :2])  # every touching pair is in one column


@pytest.mark.parametrize(
    ("kind", "angle", "supports"),
    [("pyramid", 45.0, 4), ("hex_layers", np.degrees(np.arccos(np.sqrt(2 / 3))), 3)],
)
def test_lattices_at_gap_zero_have_their_support_angle(kind, angle, supports):
    for pos, radius in layouts(kind, max_gap=0.0):
        upper = pos[:, 2] > radius + 1e-9
        assert upper.any() and len(np.unique(pos[:, 2].round(9))) == resting.LATTICE_LAYERS
        i, j, _ = bonds(pos, radius, 1e-9)
        for s in np.flatnonzero(upper):
            assert np.sum((i == s) & (pos[j, 2] < pos[s, 2])) == supports
        np.testing.assert_allclose(support_angles(pos, radius, 1e-9), angle, atol=1e-6)


def test_deposits_spread_their_support_angles():
    angles = np.concatenate([support_angles(p, r, GAP) for p, r in layouts("deposit")])
    assert angles.min() < 20 and angles.max() > 50
    assert np.all(angles < 90)


def test_the_cubic_corner_oracle_finds_tight_pack_and_nothing_else_of_the_families():
    cube = cube_positions([0, 0, 0.5], 2, 0.5, 0.0)
    assert has_cubic_corner(cube, np.full(8, 0.5), 0.0)
    square = cube[cube[:, 2] < 1]  # one layer: two directions only
    assert not has_cubic_corner(square, np.full(4, 0.5), 0.0)
    cfg = family(rest_max_gap=GAP)
    for seed in range(60):  # the held-out lattice is never produced
        s = resting_contact(cfg, np.random.default_rng(seed))
        assert not has_cubic_corner(s.pos.astype(np.float64), s.radius.astype(np.float64), GAP)


def test_rest_scenes_sit_in_their_arena_and_half_are_nudged_gently():
    cfg = family(n_min=2, n_max=3, side_min=6.0, side_max=8.0, wall_height=6.0)
    speeds = []
    for seed in range(60):
        s = resting_contact(cfg, np.random.default_rng(seed))
        half = s.planes[1:, :2].max()
        assert np.all(np.abs(s.pos[:, :2]) + s.radius[:, None] <= half + 1e-5)
        assert 1 <= s.n_spheres <= 3
        speeds.append(np.linalg.norm(s.vel, axis=1).max())
    speeds = np.asarray(speeds)
    assert speeds.max() <= cfg["rest_nudge_speed"] + 1e-6
    assert 0.3 < np.mean(speeds > 0) < 0.7


def test_the_tiny_and_small_mixes_hold_rest_scenes_in_train_and_val_only():
    for preset, share in (("tiny", 0.5), ("small", 0.25)):
        data = compose_generate([f"data={preset}"]).data
        assert data.fit_scene.rest_fraction == share
        assert data.scene.get("rest_fraction", 0.0) == 0.0  # test split: the plain family
        jobs = plan(data, {})
        assert {j.split for j in jobs if j.scene.get("rest_fraction")} == {"train", "val"}


def test_restitution_and_friction_are_drawn_independently_over_the_whole_range():
    cfg = family()
    rng = np.random.default_rng(0)
    m = np.concatenate([draw_materials(cfg, rng) for _ in range(5000)])
    assert m.shape == (15000, 4)
    e = m[:, 0]
    assert e.min() >= 0.1 and e.max() <= 0.95
    assert e.min() < 0.11 and e.max() > 0.94  # covers 0.1-0.95
    for k in (1, 2, 3):
        assert abs(np.corrcoef(e, m[:, k])[0, 1]) < 0.05
    planes = np.stack([draw_plane_materials(cfg, rng, 5) for _ in range(2000)])
    assert planes.shape == (2000, 5, 4)
    assert np.all(planes[:, :, 0] == planes[:, :1, 0])  # one restitution for a scene's planes
    assert 0.5 <= planes[..., 0].min() < 0.52 and 0.98 < planes[..., 0].max() <= 1.0
    np.testing.assert_array_equal(planes[..., 1:], np.tile([1.0, 0.0, 0.0], (2000, 5, 1)))


def test_scenes_of_the_family_carry_their_drawn_materials():
    s = build_scene(family(), np.random.default_rng(3))
    assert s.materials.shape == (3, 4) and s.plane_materials.shape == (5, 4)
    assert set(s.material.tolist()) <= {0, 1, 2}
    fixed = build_scene(
        family(material_ranges=None, plane_restitution=None), np.random.default_rng(3)
    )
    np.testing.assert_allclose(fixed.materials[:, 0], [0.7, 0.5, 0.3])
    assert fixed.plane_materials is None


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"material_ranges": {"restitution": [0.1, 0.9]}}, "material_ranges needs exactly"),
        ({"plane_restitution": [0.5, 1.5]}, "plane_restitution must stay <= 1"),
        ({"plane_restitution": [0.9, 0.5]}, "need 0 <= low <= high"),
        ({"materials_per_scene": 0}, "materials_per_scene must be >= 1"),
    ],
)
def test_bad_material_configs_are_one_line(overrides, match):
    with pytest.raises(SceneError, match=match) as e:
        build_scene(family(**overrides), np.random.default_rng(0))
    assert "\n" not in str(e.value)
