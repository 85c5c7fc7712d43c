"""What the loggers learn of a run: the whole config as hyperparameters, a name per run of a
sweep from the experiment and its overrides, the experiment as wandb's group; and what a
training prints: none of Lightning's known-harmless warnings and tips."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import yaml
from hydra.core.hydra_config import HydraConfig
from hydra.utils import instantiate
from lightning.pytorch.utilities.warnings import PossibleUserWarning
from trainkit import SHORT, compose_train, outputs_of

from physgnn import train as train_command
from physgnn.training.quiet import quiet_lightning
from physgnn.training.tracking import NAME_CHARS, log_config, run_name

ROOT = Path(__file__).resolve().parents[1]
# Lightning's words that a plain training printed on its first screen
HARMLESS = ("litlogger", "💡 Tip", "LeafSpec", "does not have many workers", "weights_only")


def _keys(hparams: dict) -> None:
    """The model, data, learning rate and batch size of the run, besides the recipe."""
    assert hparams["model"]["network"]["M"] == 1
    assert hparams["data"]["name"] == "tiny"
    assert hparams["lit"]["optimizer"]["lr"] > 0
    assert hparams["datamodule"]["batch_size"] == 4
    assert "noise" in hparams and "seed" in hparams  # the Lightning module's own


def test_a_run_name_is_readable_file_safe_and_apart_past_its_length():
    assert run_name("baseline", ["model.network.M=3", "seed=1"]) == "baseline_network.M=3_seed=1"
    assert run_name("study", ["data.dir=/a/b c"]) == "study_data.dir=-a-b-c"
    long = [f"trainer.key{i}=value{i}" for i in range(30)]
    one, two = run_name("x", [*long, "seed=0"]), run_name("x", [*long, "seed=1"])
    assert len(one) == len(two) == NAME_CHARS and one != two


def test_the_runs_of_a_multirun_have_their_own_names_and_the_whole_config(
    tiny_dataset, tmp_path, monkeypatch
):
    sweep = tmp_path / "sweep"
    args = ["-m", "seed=0,1", "data=tiny", "logger=tensorboard", *SHORT]
    monkeypatch.setattr(sys, "argv", ["physgnn.train", *args])
    train_command.main(
        [*args, f"paths.outputs={outputs_of(tiny_dataset)}", f"hydra.sweep.dir={sweep}"]
    )
    runs = sorted(sweep.glob("*/tensorboard/*/hparams.yaml"))
    names = [path.parent.name for path in runs]
    assert len(names) == 2 and names[0] != names[1], names
    assert names[0].startswith("baseline_seed=0_data=tiny_logger=tensorboard_network.M=1_")
    for path in runs:
        _keys(yaml.safe_load(path.read_text()))


def test_the_csv_logger_keeps_the_whole_config(tiny_dataset, tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["physgnn.train"])
    train_command.main(
        ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={tmp_path}", *SHORT]
    )
    _keys(yaml.safe_load((tmp_path / "csv" / "version_0" / "hparams.yaml").read_text()))


@pytest.mark.skipif(importlib.util.find_spec("wandb") is None, reason="wandb not installed")
def test_wandb_groups_the_runs_of_an_experiment(tmp_path, monkeypatch):
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    cfg = compose_train(["logger=wandb", f"run_dir={tmp_path}", "model.network.M=3", "seed=1"])
    HydraConfig.instance().set_config(cfg)
    logger = instantiate(cfg.logger)
    try:
        assert logger.experiment.group == "baseline"
        assert logger.experiment.name == "baseline_logger=wandb_network.M=3_seed=1"
        log_config([logger], cfg)
        assert logger.experiment.config["model"]["network"]["M"] == 3
    finally:
        logger.experiment.finish()


def test_a_tiny_training_prints_none_of_lightnings_harmless_warnings(tiny_dataset, tmp_path):
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={tmp_path}"]
    done = subprocess.run(
        [sys.executable, "-m", "physgnn.train", *args, *SHORT],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    assert done.returncode == 0, done.stderr[-2000:]
    printed = done.stdout + done.stderr
    assert "finished after 2 steps" in printed
    assert not [words for words in HARMLESS if words in printed], printed


def test_the_filters_are_by_message_not_by_kind():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        quiet_lightning()
        quiet_lightning()  # twice: each filter once
        for message, category in [
            ("The 'val_dataloader' does not have many workers ...", PossibleUserWarning),
            ("`isinstance(treespec, LeafSpec)` is deprecated, use ...", FutureWarning),
            ("The 'val_dataloader' holds NaN", PossibleUserWarning),
            ("something else is deprecated", FutureWarning),
        ]:
            warnings.warn(message, category, stacklevel=1)
    assert [str(w.message) for w in caught] == [
        "The 'val_dataloader' holds NaN",
        "something else is deprecated",
    ]
