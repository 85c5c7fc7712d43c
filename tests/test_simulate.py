"""python -m physgnn.simulate on a tiny scene: truth only, with an untrained model, and with a
real (tiny) trained run."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from simdata import learned
from truthkit import SCENE

import physgnn.evaluation.simulate as S
from physgnn import CONF_DIR, metrics
from physgnn.cli import compose_config
from physgnn.data.dataset import read_split
from physgnn.evaluation import simulate_learned
from physgnn.groundtruth.scenefile import scene_from_dict
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.rollout import rollout
from physgnn.simulate import main
from physgnn.training.runs import load_run

EXAMPLE = Path(CONF_DIR) / "scene" / "head_on.yaml"


def load_scene_text(text: str):
    """The scene of a scene file's text (what simulate records as ``scene_config``)."""
    return scene_from_dict(yaml.safe_load(text))


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(SCENE)
    return path


def test_truth_only_writes_hdf5_metrics_and_video(scene_file, tmp_path, capsys):
    out = tmp_path / "out"
    main([f"scene_file={scene_file}", f"out={out}"])
    assert "tiny: 2 spheres, 6 frames" in capsys.readouterr().out
    with h5py.File(out / "simulate.h5") as f:
        assert list(f) == ["truth"] and f["truth/pos"].shape == (6, 2, 3)
    result = json.loads((out / "metrics.json").read_text())
    assert result["run"] is None and result["metrics"]["energy_gain"] >= 0
    for kind in ("gif", "png", "mp4"):
        assert (out / result["files"][kind].split("/")[-1]).stat().st_size > 0


def test_learned_rollout_from_the_same_start(scene_file, tmp_path, monkeypatch):
    sim = learned(H=1, M=1, hidden=8).eval()
    monkeypatch.setattr(
        S,
        "learned",
        lambda run, truth, steps, cache, threads: (
            simulate_learned.rollout_prediction(sim, truth),
            {"run": run},
        ),
    )
    out = tmp_path / "out"
    args = [f"scene_file={scene_file}", f"out={out}", "run=R", "video=false"]
    result = S.run(compose_config("simulate", args))
    with h5py.File(out / "simulate.h5") as f:
        assert list(f) == ["prediction", "truth"]
        assert (f["truth/pos"][:2] == f["prediction/pos"][:2]).all()  # H + 1 start frames
    assert {"mse", "chamfer", "energy_gain", "depth_sphere"} <= set(result["metrics"])


def test_a_trained_run_end_to_end(tiny_run, scene_file, tmp_path, capsys):
    out = tmp_path / "out"
    main([f"scene_file={scene_file}", f"run={tiny_run}", f"out={out}", "frames=8"])
    printed = capsys.readouterr().out
    result = json.loads((out / "metrics.json").read_text())
    simulator, _, info = load_run(tiny_run)
    assert result["run"] == info["checkpoint"] and result["n_frames"] == 8
    groups = {t.attrs["group"]: t for t in read_split(out / "simulate.h5")}
    truth, pred = groups["truth"], groups["prediction"]
    expected = rollout(simulator, [truth])[0]  # the same rollout, from the truth on file
    assert pred.n_frames == expected.n_frames == 8 and pred.diverged_at is None
    np.testing.assert_allclose(pred.pos, expected.pos, rtol=1e-6, atol=1e-6)
    mse = metrics.trajectory_metrics(expected, truth, horizon=20)["mse"]
    assert result["metrics"]["mse"] == pytest.approx(mse, rel=1e-5) and mse > 0
    assert f"mse {mse:.3g}" in printed
    for kind in ("gif", "mp4", "png"):
        assert Path(result["files"][kind]).stat().st_size > 0


def test_default_out_follows_paths_outputs_as_every_command(scene_file, tmp_path, monkeypatch):
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    monkeypatch.delenv("PHYSGNN_OUTPUTS", raising=False)
    main([f"scene_file={scene_file}", "video=false"])
    assert (cwd / "outputs" / "simulate" / "tiny" / "metrics.json").is_file()
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path / "env"))
    main([f"scene_file={scene_file}", "video=false"])
    assert (tmp_path / "env" / "simulate" / "tiny" / "metrics.json").is_file()
    main([f"scene_file={scene_file}", "video=false", f"paths.outputs={tmp_path / 'arg'}"])
    assert (tmp_path / "arg" / "simulate" / "tiny" / "metrics.json").is_file()
    assert [p.name for p in cwd.iterdir()] == ["outputs"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "scene: missing (scene=NAME: an example or a scene family of conf/scene/"),
        (["scene=throw", "scene_file=x.yaml"], "scene: both given: give one"),
        (
            ["scene_file=x.yaml", "frame=3"],
            "frame=3: frame is not a key of the simulate config: did you mean frames?",
        ),
        (["scene=x.yaml"], "scene=x.yaml: no 'x.yaml' in the config group scene (options: "),
        (["scene=my/x.yaml"], "a YAML scene file of yours is scene_file=my/x.yaml"),
        (["scene_file=/nonexistent.yaml"], "does not exist"),
        (["scene_file=x.yaml", "constraints=-1"], "constraints must be a whole number >= 0"),
        (["scene=ood_spaced_drop", "seed=-1"], "seed must be a whole number >= 0"),
        (["scene=throw", "threads=0"], "threads must be a whole number >= 1"),
    ],
)
def test_errors_are_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and message in err and err.count("\n") == 1


def test_scene_names_an_example_or_a_family_of_the_scene_group(tmp_path):
    """``scene=head_on`` is the example file conf/scene/head_on.yaml, as ``scene_file=`` reads
    it; ``scene=ood_spaced_drop`` one scene of that family, drawn with ``seed``."""
    runs = {}
    for name, args in {
        "group": ["scene=head_on"],
        "file": [f"scene_file={EXAMPLE}"],
        "family": ["scene=ood_spaced_drop", "seed=3"],
    }.items():
        cfg = compose_config(
            "simulate", [*args, "frames=4", "video=false", f"out={tmp_path / name}"]
        )
        runs[name] = S.run(cfg)
    assert runs["group"]["metrics"] == runs["file"]["metrics"] and runs["group"]["n_frames"] == 4
    assert runs["family"]["scene"] == "ood_spaced_drop" and runs["family"]["n_frames"] == 4
    h5 = read_split(tmp_path / "family" / "simulate.h5")[0]
    assert load_scene_text(h5.attrs["scene_config"]).n_spheres == runs["family"]["n_spheres"]


def test_help_names_the_keys_and_the_scenes(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    out = capsys.readouterr().out
    assert e.value.code in (0, None) and "scene_file: null" in out and "throw" in out


def test_missing_run_folder(scene_file, tmp_path, capsys):
    args = [f"scene_file={scene_file}", f"out={tmp_path / 'out'}", "run=/no/such/run"]
    with pytest.raises(SystemExit):
        main([*args, "video=false"])
    assert "run folder /no/such/run does not exist" in capsys.readouterr().err


def test_constraints_wrap_the_learned_simulator_and_are_recorded(scene_file, tmp_path, monkeypatch):
    sim = learned(H=1, M=1, hidden=8, gravity_prior=True).eval()
    fake = (sim, None, {"checkpoint": "ck"})
    monkeypatch.setattr(simulate_learned, "load_run", lambda run_dir: fake)
    out = tmp_path / "out"
    argv = [f"scene_file={scene_file}", f"out={out}", f"run={tmp_path}", "constraints=4"]
    result = S.run(compose_config("simulate", [*argv, "video=false"]))
    assert result["constraints"] == 4
    groups = {t.attrs["group"]: t for t in read_split(out / "simulate.h5")}
    expected = rollout(ConstrainedSimulator(sim, 4), [groups["truth"]])[0]
    np.testing.assert_allclose(groups["prediction"].pos, expected.pos, rtol=1e-6, atol=1e-6)
