"""Training configs and the train command in-process, shared by the training, fault and
writer tests: the short recipe (:data:`SHORT`), :func:`config`, :func:`run_main`."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from physgnn import CONF_DIR
from physgnn import train as train_command

SHORT = [
    "model.network.M=1",
    "model.network.hidden=16",
    "trainer.max_epochs=1",
    "trainer.max_time=null",
    "trainer.enable_progress_bar=false",
    "trainer.enable_model_summary=false",
    "datamodule.batch_size=4",
    "datamodule.pairs_per_epoch=8",
    "datamodule.val_pairs=8",
]


def outputs_of(tiny_dataset) -> Path:
    return Path(tiny_dataset).parents[1]  # <outputs>/data/tiny


def config(tiny_dataset, run_dir, *overrides):
    base = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={run_dir}"]
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("train", overrides=base + list(overrides))


def run_main(monkeypatch, capsys, *args) -> tuple[int, str]:
    monkeypatch.setattr(sys, "argv", ["physgnn.train", *args])
    with pytest.raises(SystemExit) as info:
        train_command.main()
    return info.value.code, capsys.readouterr().err.strip().splitlines()[-1]


def compose_train(overrides: list[str]):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("train", overrides=overrides, return_hydra_config=True)
