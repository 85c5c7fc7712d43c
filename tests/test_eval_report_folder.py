"""A report folder holds one eval: a second eval replaces the first's outputs whole, and an
interrupted eval leaves the previous report as it was."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fakeruns import Exploding, Falling, eval_cfg, evaluate_fake_runs, make_run
from omegaconf import OmegaConf

import physgnn.evaluation.evaluate as ev
import physgnn.training.runs

# pybullet on the same work and its Pareto figures are tests/test_eval.py's: not re-run here
NO_PYBULLET = "pybullet=null"


def evaluate_again(outputs: Path, *overrides: str) -> Path:
    """:func:`evaluate_fake_runs` once more on the outputs it made."""
    sims = {"baseline": Falling(), "ablation_M": Exploding()}
    data = outputs / "data" / "hand"

    def fake_load_run(run_dir):
        experiment = json.loads((Path(run_dir) / "run.json").read_text())["experiment"]
        return sims[experiment], OmegaConf.create({"datamodule": {"data_dir": str(data)}}), {}

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(physgnn.training.runs, "load_run", fake_load_run)
        return ev.evaluate(eval_cfg(f"paths.outputs={outputs}", *overrides))


def test_a_second_eval_without_videos_links_none_of_the_first(tmp_path):
    outputs = tmp_path / "outputs"
    first = evaluate_fake_runs(outputs, "video_frames=3", NO_PYBULLET)
    videos = outputs / "report" / "videos"
    assert any(videos.glob("*.gif")) and "videos/" in first.read_text()
    (outputs / "report" / "notes.txt").write_text("mine")  # not an eval output: kept
    second = evaluate_again(outputs, "videos=false", NO_PYBULLET)
    assert not videos.exists() and "videos/" not in second.read_text()
    assert (outputs / "report" / "notes.txt").read_text() == "mine"
    assert not (outputs / "report.partial").exists()


def test_an_interrupted_eval_leaves_the_last_report(tmp_path, monkeypatch):
    outputs = tmp_path / "outputs"
    report = evaluate_fake_runs(outputs, "videos=false", NO_PYBULLET)
    before = {p.name: p.read_bytes() for p in report.parent.iterdir() if p.is_file()}

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(ev, "write_report", interrupted)
    with pytest.raises(KeyboardInterrupt):
        evaluate_again(outputs, "videos=false", NO_PYBULLET)
    after = {p.name: p.read_bytes() for p in report.parent.iterdir() if p.is_file()}
    assert after == before and not (outputs / "report.partial").exists()


def test_overwrite_into_a_folder_of_yours_keeps_your_files_in_rollouts_and_figures(tmp_path):
    mine = tmp_path / "mine"
    for name in ("notes.txt", "rollouts/my_solver/test.h5", "figures/my_plot.png"):
        (mine / name).parent.mkdir(parents=True, exist_ok=True)
        (mine / name).write_text("mine")
    overrides = ("videos=false", "save_rollouts=true", "overwrite=true", NO_PYBULLET)
    evaluate_fake_runs(tmp_path / "outputs", f"report_dir={mine}", *overrides)
    for name in ("notes.txt", "rollouts/my_solver/test.h5", "figures/my_plot.png"):
        assert (mine / name).read_text() == "mine", name
    assert (mine / "rollouts" / "runs" / "baseline" / "2026-01-01_00-00-00" / "test.h5").is_file()
    assert (mine / "figures" / "energy_ood.png").is_file() and (mine / "report.md").is_file()


def test_rollouts_of_a_run_outside_the_outputs_go_under_the_report_dir_only(tmp_path):
    outputs, report = tmp_path / "outputs", tmp_path / "R"
    run = make_run(tmp_path / "elsewhere" / "myrun")  # runs=<an absolute path>: its name
    overrides = (f"runs={run}", f"report_dir={report}", "videos=false", "save_rollouts=true")
    interrupted = pytest.MonkeyPatch.context()
    with interrupted as mp, pytest.raises(KeyboardInterrupt):  # SIGTERM after the rollouts
        mp.setattr(ev, "write_report", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
        evaluate_fake_runs(outputs, *overrides, NO_PYBULLET)
    assert sorted(p.name for p in run.iterdir()) == [".hydra", "run.json"]
    assert not (report / "rollouts").exists()
    evaluate_again(outputs, *overrides, NO_PYBULLET)
    assert sorted(p.name for p in run.iterdir()) == [".hydra", "run.json"]
    saved = report / "rollouts" / Path(*run.parts[1:])  # the run's name, under rollouts/
    assert sorted(p.name for p in saved.iterdir()) == ["ood.h5", "test.h5"]
