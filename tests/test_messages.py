"""Messages that were poor: each now one line naming the key or
the file and the fix, before anything is built or launched."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import mounted_tmpfs

from physgnn import generate as generate_command
from physgnn import train as train_command
from physgnn.cli import job_dirname
from physgnn.cli import outputs as cli_outputs
from physgnn.cli.outputs import check_outputs_env
from physgnn.errors import ConfigError
from physgnn.training.resume_checks import check_checkpoint
from physgnn.training.runs import RunError, load_run


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
        (
            "datamodule.batch_size=0",
            "datamodule.batch_size must be a whole number >= 1 (pairs per step), got 0 (e.g. "
            "datamodule.batch_size=1)",
        ),
        (
            "model.network.M=0",
            "model.network.M must be a whole number >= 1 (message-passing steps), got 0 (e.g. "
            "model.network.M=1)",
        ),
        (
            "model.network.hidden=0",
            "model.network.hidden must be a whole number >= 1 (units per layer), got 0 (e.g. "
            "model.network.hidden=1)",
        ),
        (
            "lit.noise.std=-1",
            "lit.noise.std must be a number >= 0 (normalised units; 0: no noise), got -1 (the "
            "default: lit.noise.std=0.03)",
        ),
        (
            "lit.noise.rest_scale=nan",
            "lit.noise.rest_scale must be a number in (0, 1] (a factor; 1: full noise at rest), "
            "got nan (the default: lit.noise.rest_scale=0.05)",
        ),
        (
            "trainer.max_epochs=1.5",
            "trainer.max_epochs must be a whole number >= 1 or -1 or null (-1 or null: no limit), "
            "got 1.5 (e.g. trainer.max_epochs=10)",
        ),
    ],
)
def test_a_value_out_of_range_is_one_line_naming_the_key(
    tmp_path, monkeypatch, capsys, override, message
):
    run_dir = tmp_path / "run"
    line = one_line_exit(
        monkeypatch,
        capsys,
        train_command,
        "data=tiny",
        f"paths.outputs={tmp_path}",
        f"run_dir={run_dir}",
        override,
    )
    assert line == f"error: {message}"
    assert not (run_dir / "checkpoints").exists()


@pytest.mark.parametrize("seed", ["-1", "1.5"])
def test_a_bad_data_seed_is_one_line_before_any_scene(tmp_path, monkeypatch, capsys, seed):
    line = one_line_exit(
        monkeypatch,
        capsys,
        generate_command,
        "data=tiny",
        "workers=1",
        f"paths.outputs={tmp_path}",
        f"data.seed={seed}",
    )
    assert line == (
        f"error: data.seed must be a whole number from 0 to 4294967295, got {seed} "
        "(conf/data/tiny.yaml: seed; e.g. data.seed=0)"
    )
    assert not (tmp_path / "data").exists()


# --- a sweep without its dataset ------------------------------------------------------------------


def test_a_sweep_without_its_dataset_is_one_line_before_any_job(tmp_path, monkeypatch, capsys):
    stats = tmp_path / "data" / "small" / "stats.json"
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path))  # make data writes there too
    line = one_line_exit(monkeypatch, capsys, train_command, "+experiment=ablation_M")
    assert line == (
        f"error: dataset 'small' not found ({stats} is missing): run `make data PRESET=small` or "
        "`python -m physgnn.generate data=small`; no job of the sweep was launched"
    )
    assert not (tmp_path / "multirun").exists() and not (tmp_path / "runs").exists()


# --- a run's files cut short, mixed or broken -----------------------------------------------------


@pytest.fixture
def run_copy(tiny_run, tmp_path) -> Path:
    """A copy of the session's tiny run (M = 1) to damage."""
    return Path(shutil.copytree(tiny_run, tmp_path / "run"))


def cut_in_half(path: Path) -> None:
    with open(path, "r+b") as f:
        f.truncate(path.stat().st_size // 2)


def test_a_truncated_checkpoint_is_one_line_naming_it_and_the_one_that_loads(tiny_run, run_copy):
    best = next((run_copy / "checkpoints").glob("best-*.ckpt"))
    last = run_copy / "checkpoints" / "last.ckpt"
    cut_in_half(best)
    with pytest.raises(
        RunError,
        match=f"^{re.escape(str(best))} is truncated or corrupt "
        rf"\(.*\): move {best.name} away to load {re.escape(str(last))} instead, "
        "or train the run again$",
    ):
        load_run(run_copy)
    shutil.copy(best, last)  # a resume from a truncated last.ckpt suggests the best that loads
    shutil.copy(tiny_run / "checkpoints" / best.name, best)
    fix = f"train on from {best} in a new run_dir (ckpt_path={best} run_dir=<a new folder>)"
    with pytest.raises(
        RunError,
        match=f"^{re.escape(str(last))} is truncated or corrupt "
        rf"\(.*\): {re.escape(fix)}$",
    ):
        check_checkpoint(str(last), None)


def test_weights_of_another_m_name_the_key(run_copy):
    config = run_copy / ".hydra" / "config.yaml"
    config.write_text(config.read_text().replace("\n    M: 1\n", "\n    M: 2\n"))
    with pytest.raises(
        RunError,
        match=r"does not fit the model .* describes \(model\.network\.M is 1 in "
        r"the weights, 2 in the config\): the weights and the config are of "
        "different runs",
    ):
        load_run(run_copy)


def test_a_broken_run_config_is_one_line_naming_it(run_copy):
    config = run_copy / ".hydra" / "config.yaml"
    config.write_text(config.read_text() + "model: [unclosed\n")
    with pytest.raises(
        RunError,
        match=f"^{re.escape(str(config))} is not a readable config "
        r"\(.*\): restore it",
    ) as err:
        load_run(run_copy)
    assert "\n" not in str(err.value)


# --- a path in a sweep's overrides --------------------------------------------------------------


def test_a_path_in_a_sweep_override_names_one_flat_job_folder(tiny_dataset, tmp_path, monkeypatch):
    sweep = tmp_path / "sweep"
    args = ["-m", "data=tiny", f"data.dir={tiny_dataset}", "lit.noise.std=-1,-2"]
    monkeypatch.setattr(
        sys,
        "argv",
        ["physgnn.train", *args, f"paths.outputs={tmp_path}", f"hydra.sweep.dir={sweep}"],
    )
    with pytest.raises(SystemExit) as exit_info:  # both jobs fail on their noise_std, at once
        train_command.main()
    assert exit_info.value.code == 1
    flat = str(tiny_dataset).replace("/", "_")
    jobs = sorted(p.name for p in sweep.iterdir() if p.is_dir())
    assert jobs == [f"{n}_data.dir={flat},data=tiny,lit.noise.std=-{n + 1}" for n in (0, 1)]
    assert job_dirname("x=/a/" + "b" * 300) == "x=_a_" + "b" * 195


# --- a read-only outputs folder -------------------------------------------------------------------


@pytest.fixture
def read_only_tmpfs(tmp_path):
    """A real read-only filesystem (root only: it mounts a tmpfs)."""
    with mounted_tmpfs(tmp_path / "ro", "ro,size=1m") as mount:
        yield mount


@pytest.mark.parametrize("module", [train_command, generate_command])
def test_a_read_only_outputs_folder_is_one_line(read_only_tmpfs, monkeypatch, capsys, module):
    outputs = read_only_tmpfs / "outputs"
    line = one_line_exit(monkeypatch, capsys, module, "data=tiny", f"paths.outputs={outputs}")
    assert line == (
        f"error: paths.outputs={outputs} cannot be written (read-only file system: "
        f"{read_only_tmpfs}): choose a writable paths.outputs (or PHYSGNN_OUTPUTS)"
    )
    assert len(capsys.readouterr().err.splitlines()) == 0  # nothing before it either


def test_a_command_writing_elsewhere_is_not_held_to_paths_outputs(monkeypatch):
    monkeypatch.setattr(
        cli_outputs, "unwritable", lambda f: "read-only" if f.startswith("/ro") else None
    )
    check_outputs_env(["paths.outputs=/ro/x", "report_dir=/rw/r"], "report_dir")  # eval
    check_outputs_env(["paths.outputs=/ro/x"], None)  # data_report reads only
    with pytest.raises(
        ConfigError,
        match=r"^report_dir=/ro/r cannot be written \(read-only\): "
        "choose a writable report_dir$",
    ):
        check_outputs_env(["paths.outputs=/rw", "report_dir=/ro/r"], "report_dir")
    with pytest.raises(ConfigError, match=r"^paths.outputs=/ro cannot be written"):
        check_outputs_env(["paths.outputs=/ro"], "report_dir")  # its report_dir lies under it
    check_outputs_env(["paths.outputs=/ro", "run_dir=/rw/run"])  # train reads data from /ro


# --- make from another folder -----------------------------------------------------------------


def test_make_from_another_folder_is_one_line_naming_the_checkout(tmp_path):
    root = Path(__file__).resolve().parents[1]
    if shutil.which("make") is None:
        pytest.skip("no make on this machine")
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL")}
    done = subprocess.run(
        ["make", "-f", str(root / "Makefile"), "help"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )

    assert done.returncode == 2 and done.stdout == ""
    (line,) = done.stderr.strip().splitlines()
    assert f"run make in the checkout: make -C {root} <target>, or cd {root}" in line
    ok = subprocess.run(["make", "-C", str(root), "help"], env=env, capture_output=True, text=True)
    assert ok.returncode == 0 and "test" in ok.stdout
