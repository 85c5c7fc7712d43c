"""``make eval`` on fake run folders and a hand-built dataset, shared by the eval tests: run
folders (:func:`make_run`, :func:`fake_outputs`), fake simulators, :func:`evaluate_fake_runs`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from simdata import trajectory

import physgnn.training.runs
from physgnn import CONF_DIR
from physgnn.data.dataset import write_split
from physgnn.evaluation import evaluate as ev
from physgnn.models.baselines import GravityOnlySimulator
from physgnn.report import table as report_table


def make_run(folder: Path, experiment="baseline", overrides=(), seed=0, status="finished"):
    folder.mkdir(parents=True)
    (folder / ".hydra").mkdir()
    (folder / ".hydra" / "overrides.yaml").write_text("\n".join(f"- {o}" for o in overrides))
    info = {
        "status": status,
        "experiment": experiment,
        "overrides": list(overrides),
        "seed": seed,
        "train_time_s": 1.0,
    }
    (folder / "run.json").write_text(json.dumps(info))
    return folder


def fake_outputs(out: Path) -> Path:
    make_run(out / "runs" / "baseline" / "2026-01-01_00-00-00")
    make_run(out / "runs" / "baseline" / "2026-01-01_00-00-01", status="running")
    make_run(
        out / "multirun" / "ablation_M" / "t0" / "model.network.M=3,seed=1",
        "ablation_M",
        ["+experiment=ablation_M", "model.network.M=3", "seed=1"],
        seed=1,
    )
    make_run(
        out / "multirun" / "ablation_M" / "t0" / "model.network.M=5,seed=1",
        "ablation_M",
        ["model.network.M=5", "seed=1"],
        seed=1,
        status="diverged",
    )
    return out


def eval_cfg(*overrides):
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        # the stability section rolls out 2000-frame hard scenes: tests/test_stability.py
        # the invariance checks roll 2000-frame grids out: tests/test_invariances.py
        # the fake simulators have no knobs to set: tests/test_eval_settings.py
        overrides = ["stability=false", "invariance=null", "learned_settings=null", *overrides]
        return compose("eval", overrides)


class Exploding(torch.nn.Module):
    """A 'learned' simulator that blows up: speeds grow tenfold each step."""

    H = 1

    def forward(self, state):
        return 10.0 * state.vel[:, 0] + 1.0, torch.zeros_like(state.pos)


class Falling(GravityOnlySimulator):
    H = history = 1


def write_dataset(folder: Path) -> Path:
    test = [trajectory(3, 12, seed=s) for s in (1, 2)]
    ood = [trajectory(4, 12, seed=s) for s in (3, 4)]
    for traj, name in zip(ood, ("ood_cubes", report_table.SLEEP_SCENE), strict=True):
        traj.attrs["group"] = name
    for split, trajs in (("test", test), ("ood", ood)):
        write_split(folder / f"{split}.h5", trajs, {"split": split, "preset": "hand"})
    return folder


def evaluate_fake_runs(outputs: Path, *overrides: str) -> Path:
    """``make eval`` of two fake runs on a hand-built dataset: a sound one and one that
    diverges; returns report.md."""
    outputs = fake_outputs(outputs)
    data = write_dataset(outputs / "data" / "hand")
    sims = {"baseline": Falling(), "ablation_M": Exploding()}

    def fake_load_run(run_dir):
        experiment = json.loads((Path(run_dir) / "run.json").read_text())["experiment"]
        cfg = OmegaConf.create({"datamodule": {"data_dir": str(data)}})
        return sims[experiment], cfg, {}

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(physgnn.training.runs, "load_run", fake_load_run)
        return ev.evaluate(eval_cfg(f"paths.outputs={outputs}", *overrides))
