"""The notebook API (physgnn.api) and its example, examples/notebook.py, run as a script."""

from __future__ import annotations

import runpy
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from simdata import trajectory
from torch.testing import assert_close

import physgnn.api as pg
from physgnn.physics.scene import SceneError

ROOT = Path(__file__).resolve().parents[1]
IN_RANGE = [[0.5, 0.5, 0.01, 0.01]]  # a material inside the shipped model's training ranges
T = torch.as_tensor


@pytest.fixture(scope="module")
def model():
    return pg.load_model("pretrained")


def test_the_example_notebook_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.warns(pg.OutOfDistributionWarning) as caught:
        names = runpy.run_path(str(ROOT / "examples" / "notebook.py"))
    assert any("two_drops lies outside" in str(w.message) for w in caught)
    out = tmp_path / "outputs" / "notebook"
    assert (out / "throw.gif").is_file() and (out / "throw_vtk" / "spheres.vtu.series").is_file()
    assert names["pred"].n_frames == names["FRAMES"] and names["scores"]["mse"] >= 0


def test_scene_from_arrays_starts_where_it_is_told():
    pos = np.array([[0.0, 0.0, 2.0], [3.0, 0.0, 1.0]])
    vel = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    scene = pg.scene_from_arrays(pos, 0.5, vel=vel, frames=7, dt=0.05, materials=IN_RANGE)
    assert scene.n_frames == 7 and scene.dt == 0.05 and scene.n_spheres == 2
    assert_close(T(scene.pos), T(pos, dtype=torch.float32))
    assert_close(T(scene.vel), T(vel, dtype=torch.float32))
    assert_close(T(scene.angvel), torch.zeros(2, 3))
    assert scene.planes.shape == (1, 11)


def test_scene_of_a_trajectory_is_its_first_frame():
    traj = trajectory(n=3, frames=5)
    scene = pg.scene_of(traj)
    for key in ("pos", "quat", "vel", "angvel"):
        assert_close(T(getattr(scene, key)), T(getattr(traj, key)[0]))
    assert scene.n_frames == 5 and scene.dt == traj.dt


def test_roll_out_warns_only_outside_the_training_ranges(model):
    pos = np.array([[0.0, 0.0, 2.0], [3.0, 0.0, 1.0]])
    inside = pg.simulate(pg.scene_from_arrays(pos, 0.75, frames=6, materials=IN_RANGE))
    with warnings.catch_warnings():
        warnings.simplefilter("error", pg.OutOfDistributionWarning)
        pred = pg.roll_out(model, inside)
    assert pred.n_frames == 6 and pred.start == model.H
    apart = np.array([[0.0, 0.0, 2.5], [5.0, 0.0, 2.5]])  # radius 2: clear of each other
    big = pg.simulate(pg.scene_from_arrays(apart, 2.0, frames=6, materials=IN_RANGE))
    with pytest.warns(pg.OutOfDistributionWarning, match=r"radius \(m\) 2–2 \(trained on"):
        pg.roll_out(model, big)


def test_score_without_a_prediction_is_the_truths_own_physics():
    truth = trajectory(n=2, frames=6)
    scores = pg.score(None, truth)
    assert "energy_gain" in scores and "mse" not in scores


def test_export_to_hdf5_reads_back_and_an_unknown_format_is_one_line(tmp_path):
    traj = trajectory(n=2, frames=4)
    (back,) = pg.load_trajectories(pg.export(traj, tmp_path, "hdf5"))
    assert_close(T(back.pos), T(traj.pos))
    with pytest.raises(SceneError, match=r"export format 'obj' is unknown; choose one of"):
        pg.export(traj, tmp_path, "obj")
    with pytest.raises(SceneError, match="export to vtk takes one trajectory, got 2"):
        pg.export([traj, traj], tmp_path, "vtk")
