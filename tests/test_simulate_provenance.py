"""What simulate records and says: where a prediction came from, how fast, when it diverged,
and when a scene lies outside what the model was trained on."""

from __future__ import annotations

import dataclasses
import json

import h5py
from truthkit import SCENE

import physgnn.evaluation.simulate as S
from physgnn.groundtruth.scenefile import load_scene
from physgnn.rollout import VELOCITY
from physgnn.simulate import main

HUGE = SCENE.replace("radius: 0.5", "radius: 500").replace("[1.5, 0, 0.5]", "[1500, 0, 500]")


def write(tmp_path, text, name="scene.yaml"):
    path = tmp_path / name
    path.write_text(text.replace("[0, 0, 2]", "[0, 0, 2000]") if "500" in text else text)
    return path


def test_the_prediction_says_what_made_it_and_how_fast(tiny_run, tmp_path):
    scene = write(tmp_path, SCENE)
    out = tmp_path / "out"
    main([f"scene_file={scene}", f"run={tiny_run}", f"out={out}", "video=false", "constraints=2"])
    result = json.loads((out / "metrics.json").read_text())
    assert result["ms_per_frame"]["pybullet"] > 0 and result["ms_per_frame"]["learned"] > 0
    assert result["threads"] == 1  # the learned rollout's (conf/simulate.yaml: threads)
    with h5py.File(out / "simulate.h5") as f:
        pred, truth = dict(f["prediction"].attrs), dict(f["truth"].attrs)
    assert pred["made_by"] == "physgnn learned simulator" and number(pred["H"]) == 0
    assert pred["checkpoint"].startswith("best-") and number(pred["constraints"]) == 2
    assert number(pred["diverged_at"]) == -1 and pred["engine"] == "" and pred["substeps"] == 0
    assert pred["velocity"] == VELOCITY[True] and number(pred["ms_per_frame"]) > 0  # its own
    assert truth["velocity"] == "the engine's (pybullet)" and truth["engine"] != ""


def test_a_scene_far_outside_training_is_named_in_one_warning_line(tiny_run, tmp_path, capsys):
    scene = write(tmp_path, HUGE)
    out = tmp_path / "out"
    main([f"scene_file={scene}", f"run={tiny_run}", f"out={out}", "video=false", "frames=5"])
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning")]
    assert len(err) == 1 and "lies outside what the run was trained on" in err[0]
    assert "radius (m) 500–500 (trained on 0.5–1)" in err[0] and "mass (kg)" in err[0]
    assert json.loads((out / "metrics.json").read_text())["warnings"]


def test_a_diverged_prediction_reports_no_metrics(tmp_path, monkeypatch, capsys):
    scene = write(tmp_path, SCENE)

    def diverged(run, truth, steps, cache, threads):
        cut = dataclasses.replace(truth.truncated(3), diverged_at=3)
        return cut, {"checkpoint": "ck", "run": "r", "H": 1, "constraints": 0}

    monkeypatch.setattr(S, "learned", diverged)
    out = tmp_path / "out"
    main([f"scene_file={scene}", "run=R", f"out={out}", "video=false"])
    printed = capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    assert metrics["diverged_at"] == 3 and metrics["mse"] is None and metrics["chamfer"] is None
    assert "DIVERGED at frame 3: no metrics" in printed and "mse 0" not in printed
    with h5py.File(out / "simulate.h5") as f:
        assert json.loads(f["prediction"].attrs["diverged_at"]) == 3


def test_a_long_simulation_reports_its_frames(tmp_path, monkeypatch):
    seen = []
    real = S.engine_simulate
    monkeypatch.setattr(S, "LONG", 0)  # every simulation counts as long

    def watched(scene, on_frame=None):
        return real(scene, on_frame=lambda done: (seen.append(done), on_frame(done)))

    monkeypatch.setattr(S, "engine_simulate", watched)
    truth = S.simulate_with_progress(load_scene(write(tmp_path, SCENE)))
    assert seen == list(range(2, truth.n_frames + 1))


def number(value):
    """An extra attribute's value: the extra attrs are written as JSON text."""
    return json.loads(value) if isinstance(value, str) else value
