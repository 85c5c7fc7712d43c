"""python -m physgnn.simulate on a tiny scene: truth only, and with an (untrained) model."""

from __future__ import annotations

import json

import h5py
import pytest
from simdata import STATS

import physgnn.evaluation.simulate as S
from physgnn.models.learned import LearnedSimulator
from physgnn.simulate import main

SCENE = """
name: tiny
dt: 0.1
frames: 6
spheres:
  - {radius: 0.5, position: [0, 0, 2], velocity: [1, 0, 0]}
  - {radius: 0.5, position: [1.5, 0, 0.5]}
"""


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(SCENE)
    return path


def test_truth_only_writes_hdf5_metrics_and_video(scene_file, tmp_path, capsys):
    out = tmp_path / "out"
    main([f"scene={scene_file}", f"out={out}"])
    assert "tiny: 2 spheres, 6 frames" in capsys.readouterr().out
    with h5py.File(out / "simulate.h5") as f:
        assert list(f) == ["truth"] and f["truth/pos"].shape == (6, 2, 3)
    result = json.loads((out / "metrics.json").read_text())
    assert result["run"] is None and result["metrics"]["energy_gain"] >= 0
    for kind in ("gif", "png", "mp4"):
        assert (out / result["files"][kind].split("/")[-1]).stat().st_size > 0


def test_learned_rollout_from_the_same_start(scene_file, tmp_path, monkeypatch):
    sim = LearnedSimulator(STATS, H=1, M=1, hidden=8).eval()
    monkeypatch.setattr(S, "learned", lambda run, truth: (S.rollout_prediction(sim, truth), run))
    out = tmp_path / "out"
    result = S.run(S.parse_args([f"scene={scene_file}", f"out={out}", "run=R", "video=false"]))
    with h5py.File(out / "simulate.h5") as f:
        assert list(f) == ["prediction", "truth"]
        assert (f["truth/pos"][:2] == f["prediction/pos"][:2]).all()  # H + 1 start frames
    assert {"mse", "chamfer", "energy_gain", "depth_sphere"} <= set(result["metrics"])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "missing scene=FILE"),
        (["scene=x.yaml", "frame=3"], "bad argument 'frame=3'"),
        (["scene=/nonexistent.yaml"], "does not exist"),
    ],
)
def test_errors_are_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and message in err and err.count("\n") == 1


def test_missing_run_folder(scene_file, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main([f"scene={scene_file}", f"out={tmp_path}", "run=/no/such/run", "video=false"])
    assert "run folder /no/such/run does not exist" in capsys.readouterr().err
