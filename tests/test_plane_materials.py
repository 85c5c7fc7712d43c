"""Plane materials: the engine bounces a sphere off a plane with the product of restitutions,
the dataset stores ``plane_materials`` (and reads a file without it as the former planes'),
and the simulator's states carry it as ``plane_materials [S, 4]``."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest
import torch
from handmade import linear_traj
from truthkit import flight_apexes, spheres

from physgnn.data.dataset import read_split, write_split
from physgnn.data.pairs import PairDataset
from physgnn.data.state import TrajectoryFrames, subset_state
from physgnn.groundtruth.engine import simulate
from physgnn.physics.scene import PLANE_MATERIAL, SceneError


@pytest.mark.parametrize(("e", "e_plane"), [(0.9, 0.5), (0.5, 1.0)])
def test_a_bounce_off_a_plane_has_the_product_of_restitutions(e, e_plane):
    h0 = 10.0
    scene = spheres([0, 0, h0 + 0.5], material=(e, 0.5, 0.0, 0.0), n_frames=50)
    scene.plane_materials = np.array([[e_plane, 1.0, 0.0, 0.0]], np.float32)
    traj = simulate(scene)
    np.testing.assert_array_equal(traj.plane_materials, scene.plane_materials)
    assert flight_apexes(traj, 0.5)[0] / h0 == pytest.approx((e * e_plane) ** 2, rel=0.1)


def test_plane_materials_must_match_the_planes():
    scene = spheres([0, 0, 2.0])
    scene.plane_materials = np.ones((2, 4), np.float32)
    with pytest.raises(SceneError, match=r"plane_materials has shape \(2, 4\), expected \(1, 4\)"):
        scene.validate()
    scene.plane_materials = np.array([[1.5, 1.0, 0.0, 0.0]], np.float32)
    with pytest.raises(SceneError, match="restitution <= 1"):
        scene.validate()


def test_plane_materials_round_trip_and_old_files_read_as_the_former_planes(tmp_path):
    new = dataclasses.replace(
        linear_traj(name="new"), plane_materials=np.array([[0.6, 1.0, 0.0, 0.0]], np.float32)
    )
    old = linear_traj(name="old")
    write_split(tmp_path / "train.h5", [new, old], {"split": "train"})
    with h5py.File(tmp_path / "train.h5") as f:
        assert "plane_materials" in f["traj_00000"] and "plane_materials" not in f["traj_00001"]
    got_new, got_old = read_split(tmp_path / "train.h5")
    np.testing.assert_array_equal(got_new.plane_materials, new.plane_materials)
    assert got_old.plane_materials is None
    np.testing.assert_array_equal(got_old.plane_coefficients, [PLANE_MATERIAL])


def test_states_and_batches_carry_plane_materials():
    a = dataclasses.replace(
        linear_traj(name="a"), plane_materials=np.array([[0.6, 1.0, 0.0, 0.0]], np.float32)
    )
    b = linear_traj(name="b", n=3)
    state = TrajectoryFrames(a).state(2, 1)
    torch.testing.assert_close(state.plane_materials, torch.tensor([[0.6, 1.0, 0.0, 0.0]]))
    sub = subset_state(state, torch.tensor([True, False]))  # spheres go, planes stay
    torch.testing.assert_close(sub.plane_materials, state.plane_materials)
    batch = PairDataset([a, b], H=1).batch(torch.tensor([0, 4]))
    want = torch.tensor([[0.6, 1.0, 0.0, 0.0], PLANE_MATERIAL])
    torch.testing.assert_close(batch.plane_materials, want)
    assert batch.plane_materials.shape == (batch.planes.shape[0], 4)


def test_scene_files_keep_plane_restitutions(tmp_path):
    from truthkit import family

    from physgnn.groundtruth.families import build_scene
    from physgnn.groundtruth.scenefile import load_scene, scene_to_dict, write_scene

    scene = build_scene(family(), np.random.default_rng(1))  # a drawn plane restitution
    back = load_scene(write_scene(tmp_path / "s.yaml", scene))
    np.testing.assert_allclose(back.plane_materials, scene.plane_materials, atol=1e-7)
    d = scene_to_dict(scene)
    assert d["ground_restitution"] == d["planes"][0]["restitution"] < 1
    plain = build_scene(family(plane_restitution=None), np.random.default_rng(1))
    d = scene_to_dict(plain)
    assert "ground_restitution" not in d and "restitution" not in d["planes"][0]
    assert load_scene(write_scene(tmp_path / "p.yaml", plain)).plane_materials is None
    plain.plane_materials = np.tile([0.5, 0.3, 0.0, 0.0], (5, 1))
    with pytest.raises(SceneError, match="holds a plane's restitution only"):
        scene_to_dict(plain)


def test_a_plane_restitution_outside_0_1_is_one_line():
    from physgnn.groundtruth.scenefile import scene_from_dict

    d = {"spheres": [{"radius": 0.5, "position": [0, 0, 2]}], "ground_restitution": 1.5}
    with pytest.raises(SceneError, match=r"scene: ground_restitution: must be in \[0, 1\]"):
        scene_from_dict(d)
