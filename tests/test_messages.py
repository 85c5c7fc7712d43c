"""Poor messages of issue 37 ("Nothing lost, third round"): each now one line naming the key or
the file and the fix, before anything is built or launched."""

from __future__ import annotations

import sys

import pytest

from physgnn import generate as generate_command
from physgnn import train as train_command


def one_line_exit(monkeypatch, capsys, module, *args) -> str:
    """Run ``module.main()`` with ``args``; its exit code is 2 and its last stderr line, the
    error, is returned (Hydra's log lines come before it)."""
    monkeypatch.setattr(sys, "argv", [module.__name__, *args])
    with pytest.raises(SystemExit) as info:
        module.main()
    assert info.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


# --- values the constructors refused in Hydra's generic wrapper ----------------------------------


@pytest.mark.parametrize(
    "override,message",
    [
        ("datamodule.batch_size=0", "datamodule.batch_size must be a whole number >= 1 (pairs per "
         "step), got 0"),
        ("model.M=0", "model.M must be a whole number >= 1 (message-passing steps), got 0"),
        ("model.hidden=0", "model.hidden must be a whole number >= 1 (units per layer), got 0"),
        ("lit.noise_std=-1", "lit.noise_std must be a number >= 0 (input noise, normalised units; "
         "0: none), got -1"),
        ("lit.noise_rest_scale=nan", "lit.noise_rest_scale must be a number > 0 and <= 1 (a "
         "factor; 1: full noise at rest), got nan"),
        ("trainer.max_epochs=1.5", "trainer.max_epochs must be a whole number (>= 1; -1: no "
         "limit), got 1.5"),
    ],
)  # fmt: skip
def test_a_value_out_of_range_is_one_line_naming_the_key(tmp_path, monkeypatch, capsys, override,
                                                         message):  # fmt: skip
    run_dir = tmp_path / "run"
    line = one_line_exit(monkeypatch, capsys, train_command, "data=tiny",
                         f"paths.outputs={tmp_path}", f"run_dir={run_dir}", override)  # fmt: skip
    assert line == f"error: {message}"
    assert not (run_dir / "checkpoints").exists()


@pytest.mark.parametrize("seed", ["-1", "1.5"])
def test_a_bad_data_seed_is_one_line_before_any_scene(tmp_path, monkeypatch, capsys, seed):
    line = one_line_exit(monkeypatch, capsys, generate_command, "data=tiny", "workers=1",
                         f"paths.outputs={tmp_path}", f"data.seed={seed}")  # fmt: skip
    assert line == (
        f"error: data.seed must be a whole number from 0 to 4294967295, got {seed} "
        "(conf/data/tiny.yaml: seed; e.g. data.seed=0)"
    )
    assert not (tmp_path / "data").exists()


# --- a sweep without its dataset ------------------------------------------------------------------


def test_a_sweep_without_its_dataset_is_one_line_before_any_job(tmp_path, monkeypatch, capsys):
    stats = tmp_path / "data" / "small" / "stats.json"
    line = one_line_exit(monkeypatch, capsys, train_command, "+experiment=ablation_M",
                         f"paths.outputs={tmp_path}")  # fmt: skip
    assert line == (
        f"error: dataset 'small' not found ({stats} is missing): run `make data PRESET=small` or "
        "`python -m physgnn.generate data=small`; no job of the sweep was launched"
    )
    assert not (tmp_path / "multirun").exists() and not (tmp_path / "runs").exists()
