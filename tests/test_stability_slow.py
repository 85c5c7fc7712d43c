"""Slow cases of the stability suite (``make test-slow``): a 2-layer pile in pybullet, a trained
model on the resting pile for 2000 frames, and the real CLIs' configuration errors."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import physgnn.evaluation.stability as S
from physgnn import CONF_DIR
from physgnn.groundtruth import hard
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import build_scene
from physgnn.training.runs import load_run
from physgnn.training.train import train

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def scene_cfg(name: str, **overrides) -> dict:
    cfg = OmegaConf.to_container(OmegaConf.load(Path(CONF_DIR) / "scene" / f"{name}.yaml"))
    cfg.update(overrides)
    return cfg


def max_drift(sleeping: bool, n_frames: int) -> float:
    cfg = scene_cfg("resting_pile", n_frames=n_frames)  # 5x5 + 4x4 touching spheres
    traj = simulate(build_scene(cfg, np.random.default_rng(0)), {"sleeping": sleeping})
    assert np.isfinite(traj.pos).all()
    return float((np.linalg.norm(traj.pos - traj.pos[0], axis=-1) / traj.radius).max())


def test_engine_keeps_the_two_layer_pile_at_rest_for_2000_frames():
    # Measured (pybullet 3.2.7, default settings, Bullet sleeping on): 1.05e-3 radii, all of
    # it in the first 21 frames while the contacts settle (3.5 s). Bound 5x.
    assert max_drift(True, 2000) < 5e-3


def test_engine_without_sleeping_creeps_slowly():
    # Without sleeping the solver creeps about linearly: measured 1.54e-2 radii at frame 500
    # (6.1e-2 at 2000). Bound 3x: a regression to a collapsing pile would be > 1 radius.
    assert max_drift(False, 500) < 5e-2


TRAIN = [
    "data=tiny",
    "model.network.M=1",
    "model.network.hidden=16",
    "trainer.max_epochs=2",
    "trainer.max_time=null",
    "trainer.enable_progress_bar=false",
    "trainer.enable_model_summary=false",
    "datamodule.batch_size=8",
    "datamodule.pairs_per_epoch=64",
    "datamodule.val_pairs=8",
]


def test_trained_model_on_the_resting_pile_reports_a_finite_drift(
    tiny_dataset, tmp_path, one_thread
):
    run_dir = tmp_path / "run"
    outputs = Path(tiny_dataset).parents[1]
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose("train", [*TRAIN, f"paths.outputs={outputs}", f"run_dir={run_dir}"])
    assert train(cfg)["status"] == "finished"
    simulator, _, _ = load_run(run_dir)
    (pile,) = hard.hard_split(tmp_path / "hard", {"resting_pile": scene_cfg("resting_pile")})
    assert pile.n_frames == 2000 and pile.n_spheres == 41
    (row,) = S.rollout_rows("tiny", "baseline", simulator, [pile], "hard")
    assert row["n_resting"] == 41  # the ground truth rests
    assert row["rest_drift"] is not None and math.isfinite(row["rest_drift"])
    assert row["n_frames"] == 2000 or row["steps_to_divergence"] == row["n_frames"] - row["start"]
    assert all(math.isfinite(row[k]) for k in ("energy_gain", "max_pen_sphere", "max_pen_ground"))
    print(f"tiny model, resting pile: {row}")


@pytest.mark.parametrize(
    "module, override, problem",
    [
        ("physgnn.train", "model.MM=3", "model.MM is not a key of the train config"),
        ("physgnn.train", "trainer=cpuu", "no 'cpuu' in the config group trainer"),
        ("physgnn.train", "+experiment=nope", "no 'nope' in the config group experiment"),
        ("physgnn.generate", "data=nope", "no 'nope' in the config group data"),
        ("physgnn.eval", "stabilty=false", "stabilty is not a key of the eval config: did you"),
    ],
)
def test_cli_config_errors_name_the_problem_without_traceback(module, override, problem, tmp_path):
    cmd = [sys.executable, "-m", module, override, f"paths.outputs={tmp_path}"]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    err = done.stderr.strip().splitlines()
    assert done.returncode != 0 and problem in err[0]
    assert "Traceback" not in done.stderr
    assert list(tmp_path.iterdir()) == []  # nothing written
