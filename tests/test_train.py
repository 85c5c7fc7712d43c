"""train(cfg) on the tiny preset: fast_dev_run, resume, determinism, load_run, CLI errors."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path
from signal import SIGTERM

import lightning as L
import numpy as np
import pytest
import torch
from trainkit import SHORT, config, outputs_of, run_main

from physgnn.data.dataset import read_split
from physgnn.files import code_commit
from physgnn.metrics import trajectory_metrics
from physgnn.rollout import rollout
from physgnn.training.build import build
from physgnn.training.progress import RunProgress
from physgnn.training.runs import checkpoint_of, load_run, read_run_json
from physgnn.training.train import TrainingInterrupted, train


def weights(path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)["state_dict"]


def test_fast_dev_run(tiny_dataset, tmp_path):
    info = train(config(tiny_dataset, tmp_path, "debug=fast", "model.network.hidden=16"))
    assert info["status"] == "debug" and info["global_step"] == 1
    assert info["pairs_seen"] == 8  # debug=fast's batch, not the default 256
    assert info["train_loss"] > 0 and info["val_loss"] > 0
    assert info["pairs_per_s"] > 0 and info["nodes_per_s"] >= info["pairs_per_s"]
    saved = json.loads((tmp_path / "run.json").read_text())
    assert saved["status"] == "debug" and saved["seed"] == 0
    assert saved["threads"] == torch.get_num_threads()  # results depend on it: recorded
    assert saved["commit"] == code_commit()  # and on the code: recorded too
    assert info["checkpoints"] == {"best": None, "last": None}
    assert not list(tmp_path.rglob("*.ckpt"))  # nothing eval could take for a trained model


@pytest.fixture(scope="module")
def runs(tiny_dataset, tmp_path_factory) -> dict:
    """Five short trainings (noise on): a, b same seed; c another seed; a straight 2-epoch
    run with a's seed, and the same run stopped by SIGTERM in its second epoch (after the
    learning rate's first decay), then resumed in its folder."""
    root = tmp_path_factory.mktemp("runs")
    out = {}
    for name, extra in {
        "a": [],
        "b": [],
        "c": ["seed=4"],
        "straight": ["trainer.max_epochs=2"],
    }.items():
        cfg = config(tiny_dataset, root / name, *SHORT, "seed=3", *extra)
        out[name] = train(cfg) | {"cfg": cfg}
    two_epochs, run_dir = [*SHORT, "seed=3", "trainer.max_epochs=2"], root / "resumed"
    signal = "+callbacks.signal"
    stop = [
        f"{signal}._target_=test_faults.SignalAt",
        f"{signal}.signum={SIGTERM}",
        f"{signal}.step=3",
    ]
    with pytest.raises(TrainingInterrupted, match="at step 3"):
        train(config(tiny_dataset, run_dir, *two_epochs, *stop))
    out["stopped"] = read_run_json(run_dir)
    out["resumed"] = train(config(tiny_dataset, run_dir, *two_epochs))
    return out


def test_same_seed_same_weights(runs):
    wa, wb = weights(runs["a"]["checkpoints"]["last"]), weights(runs["b"]["checkpoints"]["last"])
    wc = weights(runs["c"]["checkpoints"]["last"])
    assert wa.keys() == wb.keys()
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    assert not all(torch.equal(wa[k], wc[k]) for k in wa)
    assert runs["a"]["train_loss"] == runs["b"]["train_loss"] != runs["c"]["train_loss"]


def test_resume_equals_straight_training(runs):
    assert runs["a"]["epochs"] == 1 and runs["a"]["global_step"] == 2
    assert runs["stopped"]["status"] == "interrupted" and runs["stopped"]["global_step"] == 3
    resumed, straight = runs["resumed"], runs["straight"]
    assert resumed["epochs"] == 2 and resumed["global_step"] == 4
    assert resumed["pairs_seen"] == straight["pairs_seen"] == 16  # the whole run's count
    assert resumed["sessions"] == 2 and straight["sessions"] == 1
    assert resumed["train_time_s"] > runs["stopped"]["train_time_s"]
    wr, ws = weights(resumed["checkpoints"]["last"]), weights(straight["checkpoints"]["last"])
    assert all(torch.equal(wr[k], ws[k]) for k in ws)
    assert resumed["val_loss"] == straight["val_loss"]


def test_load_run_rebuilds_the_simulator(runs):
    run_dir = Path(runs["a"]["run_dir"])  # train() wrote .hydra/config.yaml, no Hydra here
    simulator, run_cfg, loaded = load_run(run_dir)
    assert loaded["checkpoint"] == runs["a"]["checkpoints"]["best"]
    assert loaded["status"] == "finished" and loaded["seed"] == 3
    assert run_cfg.model.network.M == 1 and not simulator.training
    saved = weights(loaded["checkpoint"])
    for key, value in simulator.state_dict().items():
        assert torch.equal(value, saved[f"simulator.{key}"])
    assert bool(simulator.effects_trained.all())


def logged_rollouts(run_dir: Path) -> list[dict]:
    """The rows of a run's CSV log where the rollout callback logged, values as floats."""
    with open(run_dir / "csv" / "version_0" / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return [{k: float(v) for k, v in r.items() if v} for r in rows if r["val/rollout_mse"]]


def test_the_best_checkpoint_is_chosen_on_the_evals_mse_at_the_horizon(runs, tiny_dataset):
    # tiny's horizon is 10 (its trajectories have 20 frames): val/mse10, the eval's mse<k>
    cfg, run_dir = runs["a"]["cfg"], Path(runs["a"]["run_dir"])
    assert cfg.callbacks.rollout.horizon == 10
    assert cfg.callbacks.checkpoint.monitor == "val/rollout_score"
    (logged,) = logged_rollouts(run_dir)  # one epoch, one rollout validation
    simulator, _, info = load_run(run_dir)  # the best checkpoint: that epoch's weights
    val = read_split(Path(tiny_dataset) / "val.h5")
    # independently: the eval's rollout (whole trajectory) and the eval's metric at frame H + 10
    mine = [trajectory_metrics(rollout(simulator, [t])[0], t, horizon=10)["mse10"] for t in val]
    torch.testing.assert_close(logged["val/mse10"], float(np.mean(mine)), rtol=1e-5, atol=0.0)
    diameter = float(np.mean(np.concatenate([2 * t.radius for t in val])))
    physics = 10 * logged["val/max_depth"] + 10 * logged["val/tunnelled"] + logged["val/rest_drift"]
    score = logged["val/mse10"] / diameter**2 + physics
    torch.testing.assert_close(logged["val/rollout_score"], score, rtol=1e-5, atol=0.0)
    saved = torch.load(info["checkpoint"], map_location="cpu", weights_only=False)["callbacks"]
    (state,) = [v for k, v in saved.items() if "'monitor': 'val/rollout_score'" in k]
    assert float(state["current_score"]) == pytest.approx(logged["val/rollout_score"])


def test_of_several_best_checkpoints_the_best_scored_is_measured(tmp_path):
    # a run resumed after its folder moved keeps the earlier best file beside a worse new one
    folder = tmp_path / "checkpoints"
    folder.mkdir()
    key = "ModelCheckpoint{'monitor': 'val/rollout_score', 'mode': 'min'}"
    for epoch, score in ((49, 6.8), (69, 7.7)):
        state = {"callbacks": {key: {"current_score": torch.tensor(score)}}}
        torch.save(state, folder / f"best-epoch{epoch:03d}.ckpt")
    assert checkpoint_of(tmp_path).name == "best-epoch049.ckpt"
    torch.save(
        {"callbacks": {key: {"current_score": torch.tensor(6.8)}}}, folder / "best-epoch089.ckpt"
    )
    assert checkpoint_of(tmp_path).name == "best-epoch089.ckpt"  # a tie: the latest


def test_load_run_without_checkpoint_is_clear(tmp_path):
    (tmp_path / ".hydra").mkdir()
    (tmp_path / ".hydra" / "config.yaml").write_text("model: {}\n")
    with pytest.raises(FileNotFoundError, match="no checkpoint in"):
        load_run(tmp_path)
    with pytest.raises(FileNotFoundError, match="run folder .*nothing does not exist: give"):
        load_run(tmp_path / "nothing")


def test_missing_dataset_is_one_line(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path))  # where make data writes too
    code, line = run_main(monkeypatch, capsys, "data=tiny")
    assert code == 2
    assert line.startswith("error: dataset 'tiny' not found") and "make data PRESET=tiny" in line
    # paths.outputs on the command line: make data would write elsewhere, the fix names the folder
    code, line = run_main(monkeypatch, capsys, "data=tiny", f"paths.outputs={tmp_path / 'x'}")
    assert code == 2 and f"data=tiny data.dir={tmp_path / 'x' / 'data' / 'tiny'}`" in line


def test_bad_config_value_is_one_line(monkeypatch, capsys, tiny_dataset, tmp_path):
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"hydra.run.dir={tmp_path}"]
    code, line = run_main(monkeypatch, capsys, *args, "model.graph.connectivity=nearest")
    assert code == 2 and line == (
        "error: model.graph.connectivity must be one of approach, epsilon, vmax, vi (the rules "
        "that link pairs), got 'nearest' (e.g. model.graph.connectivity=approach)"
    )


def test_non_numeric_trainer_value_is_one_line(monkeypatch, capsys, tiny_dataset, tmp_path):
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"hydra.run.dir={tmp_path}"]
    code, line = run_main(monkeypatch, capsys, *args, "trainer.max_epochs=abc")
    assert code == 2 and line == "error: trainer.max_epochs must be a number, got 'abc'"


def test_exploding_model_stops_with_one_line(monkeypatch, capsys, tiny_dataset, tmp_path):
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"hydra.run.dir={tmp_path}"]
    code, line = run_main(monkeypatch, capsys, *args, *SHORT, "lit.noise.std=1e30")
    assert code == 1 and line.startswith("error: non-finite training loss")
    assert json.loads((tmp_path / "run.json").read_text())["status"] == "diverged"


@pytest.mark.slow
def test_real_multirun_two_jobs(tiny_dataset, tmp_path):
    outputs = tmp_path / "outputs"  # the fixture's folder is read-only
    shutil.copytree(tiny_dataset, outputs / "data" / "tiny")
    cmd = [
        sys.executable,
        "-m",
        "physgnn.train",
        "-m",
        "model.network.M=1,2",
        "data=tiny",
        f"paths.outputs={outputs}",
        "experiment_name=mr",
        *SHORT[1:],
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    runs = sorted((outputs / "multirun" / "mr").glob("*/*/run.json"))
    assert [json.loads(p.read_text())["overrides"][0] for p in runs] == [
        "model.network.M=1",
        "model.network.M=2",
    ]
    assert all(json.loads(p.read_text())["status"] == "finished" for p in runs)
    names = [p.parent.name for p in runs]  # job number + overrides, without paths
    assert names[0].startswith("0_") and "model.network.M=1" in names[0] and "paths" not in names[0]
    assert names[1].startswith("1_") and "model.network.M=2" in names[1]


def test_last_checkpoint_holds_the_final_weights_after_a_mid_epoch_stop(tiny_dataset, tmp_path):
    info = train(
        config(tiny_dataset, tmp_path, *SHORT, "trainer.max_epochs=3", "+trainer.max_steps=3")
    )
    assert info["global_step"] == 3 and info["status"] == "finished"
    assert torch.load(info["checkpoints"]["last"], weights_only=True)["global_step"] == 3


def test_last_checkpoint_follows_every_epoch_not_only_the_best(tiny_dataset, tmp_path):
    # The rollout score is computed once (every 100 epochs), so no later epoch is a new best.
    once = ["callbacks.rollout.every_n_epochs=100", "callbacks.rollout.n_val_trajectories=1"]
    cfg = config(tiny_dataset, tmp_path, *SHORT, "trainer.max_epochs=3", *once)
    seen = []

    class Probe(L.Callback):
        def on_train_epoch_start(self, trainer, pl_module):
            last = tmp_path / "checkpoints" / "last.ckpt"
            if last.exists():
                seen.append(torch.load(last, map_location="cpu", weights_only=False)["epoch"])

    datamodule, lit, trainer = build(cfg, [RunProgress(), Probe()])
    trainer.fit(lit, datamodule=datamodule)
    assert seen == [0, 1]
    assert [p.name for p in (tmp_path / "checkpoints").glob("best-*")] == ["best-epoch000.ckpt"]
