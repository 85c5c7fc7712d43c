"""The notebook API refuses what the commands refuse, in one line naming the argument and the
fix, from the checks the commands use (errors.check_whole, metrics.check_tolerance,
scenefile.check_placement, runs.check_not_training)."""

from __future__ import annotations

import json
import os
import socket
import subprocess

import numpy as np
import pytest
import torch
from simdata import trajectory

import physgnn.api as pg
from physgnn.data.dataset import DatasetError
from physgnn.metrics import MetricError
from physgnn.physics.scene import SceneError
from physgnn.training.runs import PRETRAINED_DIR, RunError

POS = np.array([[0.0, 0.0, 2.0], [3.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def model():
    return pg.load_model("pretrained")


@pytest.fixture(scope="module")
def truth():
    return trajectory(n=2, frames=6)


def one_line(err) -> str:
    text = str(err.value)
    assert "\n" not in text
    return text


@pytest.mark.parametrize("tol", [-1, float("nan"), float("inf"), "0.1", True])
def test_score_refuses_a_tolerance_eval_refuses(truth, tol):
    with pytest.raises(pg.ArgumentError) as err:
        pg.score(None, truth, tol=tol)
    assert one_line(err).startswith("tol must be a number >= 0 (a fraction of the diameter")


@pytest.mark.parametrize("constraints", [-1, 1.5, "2", None])
def test_roll_out_refuses_constraints_simulate_refuses(model, truth, constraints):
    with pytest.raises(pg.ArgumentError) as err:
        pg.roll_out(model, truth, constraints=constraints)
    assert one_line(err).startswith(
        f"constraints must be a whole number >= 0 (iterations of the constraint stage; 0: the "
        f"learned model alone), got {constraints!r}"
    )


@pytest.mark.parametrize("threads", [0, 1.5, "2"])
def test_roll_out_refuses_threads_simulate_refuses(model, truth, threads):
    with pytest.raises(pg.ArgumentError) as err:
        pg.roll_out(model, truth, threads=threads)
    assert one_line(err).startswith(
        f"threads must be a whole number >= 1 or null (torch threads), got {threads!r}"
    )


def test_roll_out_runs_on_its_threads_and_gives_the_process_its_own_back(model, truth, monkeypatch):
    seen, real = [], pg.rollout
    monkeypatch.setattr(
        pg, "rollout", lambda sim, trajs: seen.append(torch.get_num_threads()) or real(sim, trajs)
    )
    before = torch.get_num_threads()
    for threads in (1, 2, None):
        pg.roll_out(model, truth, threads=threads)
    pg.roll_out(model, truth)
    assert seen == [1, 2, before, 1] and torch.get_num_threads() == before


@pytest.mark.parametrize("frames", [2.7, 1, 0, "10"])
def test_simulate_and_scene_from_arrays_refuse_frames_that_are_not_a_count(frames):
    scene = pg.scene_from_arrays(POS, 0.5, frames=3)
    with pytest.raises(
        pg.ArgumentError,
        match=rf"^frames must be a whole number >= 2 .*got {frames!r} \(e.g. frames=100\)$",
    ):
        pg.simulate(scene, frames=frames)
    with pytest.raises(pg.ArgumentError, match="^frames must be a whole number >= 2"):
        pg.scene_from_arrays(POS, 0.5, frames=frames)


def test_a_whole_float_is_a_count_not_truncated():
    assert pg.scene_from_arrays(POS, 0.5, frames=4.0).n_frames == 4


@pytest.mark.parametrize(
    "pos,radius,message",
    [
        ([[0.0, 0.0, 2.0], [0.5, 0.0, 2.0]], 0.5, "spheres[0] and spheres[1] overlap by 0.5 m"),
        ([[0.0, 0.0, 0.2]], 0.5, "spheres[0] reaches below the ground z = 0"),
        (POS, [0.5, 0.5, 0.5], "radius has shape [3], expected [2]"),
    ],
)
def test_scene_from_arrays_refuses_what_a_scene_file_refuses(pos, radius, message):
    with pytest.raises(SceneError) as err:
        pg.scene_from_arrays(pos, radius)
    assert message in one_line(err)


@pytest.mark.parametrize("max_frames", [0, -3, 1, 2.5])
def test_animate_refuses_a_film_of_fewer_than_two_frames(truth, tmp_path, max_frames):
    with pytest.raises(pg.ArgumentError, match="^max_frames must be a whole number >= 2"):
        pg.animate(truth, None, tmp_path / "film", max_frames=max_frames)
    assert not list(tmp_path.iterdir())


def test_wrong_types_name_the_argument_and_the_fix(model, truth):
    scene = pg.scene_from_arrays(POS, 0.5, frames=3)
    calls = {
        "run must be a run folder (str or Path) or 'pretrained', got int": lambda: pg.load_model(
            42
        ),
        "scene must be a Scene: load_scene('throw'), scene_from_arrays(...), got str": lambda: (
            pg.simulate("throw")
        ),
        "model must be a Model: load_model('pretrained') or load_model(run_dir), got str": (
            lambda: pg.roll_out("pretrained", truth)
        ),
        "truth must be a Trajectory: simulate(scene) gives a scene's truth, got Scene": (
            lambda: pg.roll_out(model, scene)
        ),
        "path must be a YAML scene file (str or Path) or an example's name, got int": (
            lambda: pg.load_scene(3)
        ),
        "pred must be a Trajectory (roll_out's) or None, got Scene": lambda: pg.score(scene, truth),
    }
    for message, call in calls.items():
        with pytest.raises(pg.ArgumentError) as err:
            call()
        assert one_line(err) == message


def test_load_scene_of_a_folder_says_it_is_a_folder(tmp_path):
    with pytest.raises(SceneError) as err:
        pg.load_scene(tmp_path)
    assert one_line(err) == f"scene file {tmp_path} is a folder; give a YAML scene file in it"


def test_score_names_the_truth_when_the_truth_is_not_finite(truth):
    bad = trajectory(n=2, frames=6)
    bad.pos[2, 0, 0] = np.nan
    with pytest.raises(MetricError, match="^truth pos has NaN or inf at frame 2$"):
        pg.score(None, bad)
    with pytest.raises(MetricError, match="^pred pos has NaN or inf at frame 2$"):
        pg.score(bad, truth)


def test_load_model_refuses_a_run_still_training(tmp_path):
    run = tmp_path / "run"
    (run / ".hydra").mkdir(parents=True)
    (run / ".hydra" / "config.yaml").write_text(
        (PRETRAINED_DIR / ".hydra" / "config.yaml").read_text()
    )
    trainer = subprocess.Popen(["sleep", "30"])  # stands for the training process
    info = {
        "status": "running",
        "pid": trainer.pid,
        "host": socket.gethostname(),
        "started": "2026-11-23T10:00:00",
    }
    (run / "run.json").write_text(json.dumps(info))
    try:
        with pytest.raises(RunError) as err:
            pg.load_model(run)
    finally:
        trainer.kill()
        trainer.wait()
    assert one_line(err) == (
        f"run {run} is still training (pid {trainer.pid} on {socket.gethostname()}, started "
        "2026-11-23T10:00:00): its checkpoints are mid-run; load it when it has finished"
    )
    assert os.path.exists(run / "run.json")


@pytest.mark.parametrize(
    "fields,message",
    [
        ({"quat": [[0, 0, 0, 0]]}, "scene 'arrays': quat[0]: has length 0 (needs a direction)"),
        (
            {"materials": [[1.5, 0.5, 0.001, 0.001]]},
            "scene 'arrays': materials[0].restitution: must be in [0, 1], got 1.5",
        ),
        (
            {"materials": [[0.5, -1, 0.001, 0.001]]},
            "scene 'arrays': materials[0].lateral_friction: must be >= 0, got -1",
        ),
        (
            {"effects": {"gravity": "no"}},
            "Trajectory.from_arrays: effects: effect gravity must be true or false, got 'no'",
        ),
        (
            {"effects": "no"},
            "Trajectory.from_arrays: effects must be an Effects or a dict of switches, e.g. "
            "{'gravity': False}, got str",
        ),
    ],
)
def test_scene_from_arrays_checks_values_as_a_scene_file_does(fields, message):
    with pytest.raises(SceneError) as err:
        pg.scene_from_arrays([[0.0, 0.0, 1.0]], 0.5, frames=5, **fields)
    assert one_line(err) == message


def test_scene_from_arrays_normalises_an_orientation_as_a_scene_file_does():
    scene = pg.scene_from_arrays([[0.0, 0.0, 1.0]], 0.5, quat=[[2.0, 0, 0, 0]], frames=3)
    np.testing.assert_allclose(scene.quat, [[1.0, 0, 0, 0]])


@pytest.mark.parametrize(
    "pos,got", [("abc", "'abc'"), ([0.0, 0.0, 1.0], "shape [3]"), ([[1, 2]], "shape [1, 2]")]
)
def test_scene_from_arrays_names_positions_that_are_not_n_by_3_numbers(pos, got):
    with pytest.raises(pg.ArgumentError) as err:
        pg.scene_from_arrays(pos, 0.5)
    assert one_line(err) == f"pos must be an array [N, 3] of numbers (metres), got {got}"


def test_trajectory_from_arrays_names_a_value_that_is_not_numbers():
    with pytest.raises(SceneError) as err:
        pg.trajectory_from_arrays([[[0.0, 0.0, 1.0]]], 0.5, 0.1, mass="heavy")
    assert one_line(err) == (
        "Trajectory.from_arrays: mass must be an array of numbers [1], got 'heavy'"
    )


def test_animate_refuses_a_prediction_of_another_scene(truth, tmp_path):
    other = trajectory(n=3, frames=6)
    with pytest.raises(pg.ArgumentError) as err:
        pg.animate(truth, other, tmp_path / "film")
    assert one_line(err) == (
        "pred has 3 spheres, truth 2: animate a prediction of truth's own scene "
        "(roll_out(model, truth))"
    )
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "name,advice",
    [
        (
            "trajectories.h5",
            "; if it is still to be made, an hdf5 export writes it: "
            "physgnn.api.export(trajs, '{folder}', 'hdf5')",
        ),
        (
            "simulate.h5",
            "; if it is still to be made, simulate writes it: python -m physgnn.simulate ... "
            "out={folder}",
        ),
        ("mine.h5", ""),
    ],
)
def test_load_trajectories_of_a_missing_file_says_to_check_the_path(tmp_path, name, advice):
    path = tmp_path / "export" / name
    with pytest.raises(DatasetError) as err:
        pg.load_trajectories(path)
    folder = tmp_path / "export"
    assert one_line(err) == f"HDF5 file {path} not found: check the path" + advice.format(
        folder=folder
    )
    assert "generate" not in one_line(err)
