"""Faults injected the way a user or a cluster does (README "Fault handling"): one test per
row of the fault table, plus generation and training killed in a subprocess. Nothing physgnn
did not write is replaced, every mistake is one line naming the key or file, an interrupted
run is a state that resumes, and one failing job never stops a sweep."""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import lightning as L
import pytest
import torch
from conftest import compose_generate
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from processes import start, wait_for
from trainkit import SHORT, config, outputs_of, run_main

import physgnn.groundtruth.generate as gen
from physgnn import CONF_DIR
from physgnn import eval as eval_command
from physgnn import generate as generate_command
from physgnn import simulate as simulate_command
from physgnn import train as train_command
from physgnn.ablation.registry import append_record, read_registry
from physgnn.cli import command
from physgnn.data.dataset import DATASET_MARKER
from physgnn.errors import ConfigError, interrupt_signal, sigterm_interrupts
from physgnn.evaluation.data_report import DataReportError, data_report
from physgnn.evaluation.evaluate import evaluate
from physgnn.evaluation.runs import EvalError, find_runs, load_runs
from physgnn.files import OUTPUT_MARKER, claim_folder, portable
from physgnn.training.progress import StopOnSignal
from physgnn.training.runs import read_run_json
from physgnn.training.train import TrainingInterrupted, train

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def python_sigint_handler():
    """Ctrl-C as in a terminal, whatever started the suite: a shell's background job (or
    nohup) starts Python with SIGINT ignored, and training rightly leaves an ignored signal
    ignored, so the Ctrl-C tests would see nothing."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


class SignalAt(L.Callback):
    """Sends ``signum`` to this process (``times`` times) when training reaches ``step``."""

    def __init__(self, signum: int, step: int, times: int = 1):
        self.signum, self.step, self.times = signum, step, times

    def on_train_batch_end(self, trainer, *args) -> None:
        if trainer.global_step == self.step:
            for _ in range(self.times):
                os.kill(os.getpid(), self.signum)


def signal_at(signum: int, step: int, times: int = 1) -> list[str]:
    return [
        "+callbacks.signal._target_=test_faults.SignalAt",
        f"+callbacks.signal.signum={int(signum)}",
        f"+callbacks.signal.step={step}",
        f"+callbacks.signal.times={times}",
    ]


def generate_cfg(outputs, *extra):
    return compose_generate(["data=tiny", f"paths.outputs={outputs}", "progress=false", *extra])


def copy_dataset(tiny_dataset, outputs: Path) -> Path:
    shutil.copytree(tiny_dataset, outputs / "data" / "tiny")
    return outputs / "data" / "tiny"


# --- generate into an existing folder -------------------------------------------------------


@pytest.mark.parametrize("overwrite", ["false", "true"])
def test_generate_never_replaces_a_folder_it_did_not_write(tmp_path, overwrite):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "thesis.tex").write_text("years of work")
    with pytest.raises(FileExistsError, match=f"data.dir {folder} is a folder with files that"):
        gen.generate(generate_cfg(tmp_path, f"data.dir={folder}", f"overwrite={overwrite}"))
    assert [p.name for p in tmp_path.iterdir()] == ["mine"]  # no staging folder left either
    assert (folder / "thesis.tex").read_text() == "years of work"


def test_generate_into_the_outputs_root_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    (tmp_path / "runs" / "baseline").mkdir(parents=True)  # data.dir=$PHYSGNN_OUTPUTS
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path))
    args = ["physgnn.generate", "data=tiny", "data.dir=${paths.outputs}", "overwrite=true"]
    monkeypatch.setattr(sys, "argv", [*args, f"hydra.run.dir={tmp_path}/logs"])
    with pytest.raises(SystemExit) as exit_info:
        generate_command.main()
    err = capsys.readouterr().err.strip().splitlines()
    assert exit_info.value.code == 2 and len(err) == 1
    assert err[0].startswith(f"error: data.dir {tmp_path} is a folder with files that physgnn")
    assert (tmp_path / "runs" / "baseline").is_dir()


@pytest.mark.parametrize("leftover", ["tiny.partial", "tiny.old"])
def test_a_foreign_folder_where_staging_goes_is_left_alone(tmp_path, leftover):
    (tmp_path / "data" / leftover).mkdir(parents=True)
    (tmp_path / "data" / leftover / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match=f"{leftover} is in the way and physgnn did not"):
        gen.generate(generate_cfg(tmp_path))
    assert (tmp_path / "data" / leftover / "notes.txt").read_text() == "mine"
    assert not (tmp_path / "data" / "tiny").exists()


def test_an_empty_folder_is_filled_and_a_marked_leftover_removed(tiny_dataset, tmp_path):
    (tmp_path / "data" / "tiny").mkdir(parents=True)
    copy = shutil.copytree(tiny_dataset, tmp_path / "data" / "tiny.partial")  # a killed run's
    assert (copy / DATASET_MARKER).is_file()
    out = gen.generate(generate_cfg(tmp_path, "workers=1"))
    assert sorted(p.name for p in out.parent.iterdir()) == ["tiny"]
    assert json.loads((out / DATASET_MARKER).read_text())["preset"] == "tiny"


def test_export_scene_replaces_no_file(tmp_path):
    (tmp_path / "train_traj_00000.yaml").write_text("mine")
    with pytest.raises(FileExistsError, match="already holds train_traj_00000.yaml"):
        gen.generate(generate_cfg(tmp_path, f"export_scene={tmp_path}"))
    assert (tmp_path / "train_traj_00000.yaml").read_text() == "mine"


# --- simulate and eval into an existing folder ----------------------------------------------


def folder_of_mine(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "metrics.json").write_text("mine")
    return path


def refusal(key: str, folder: Path) -> str:
    return (
        f"error: {key} {folder} is a folder with files that physgnn did not write (no "
        f"{OUTPUT_MARKER}): choose another {key}, or pass overwrite=true to write over them\n"
    )


def test_simulate_writes_over_no_folder_it_did_not_write(tmp_path, capsys):
    folder = folder_of_mine(tmp_path / "mine")
    args = [f"scene_file={ROOT / 'conf' / 'scene' / 'head_on.yaml'}", "frames=3", "video=false"]
    with pytest.raises(SystemExit) as exit_info:
        simulate_command.main([*args, f"out={folder}"])
    assert exit_info.value.code == 2 and capsys.readouterr().err == refusal("out", folder)
    assert [p.name for p in folder.iterdir()] == ["metrics.json"]
    assert (folder / "metrics.json").read_text() == "mine"
    simulate_command.main([*args, f"out={folder}", "overwrite=true"])
    assert json.loads((folder / "metrics.json").read_text())["n_frames"] == 3
    assert not (folder / OUTPUT_MARKER).exists()  # still the user's: overwrite=true each time
    simulate_command.main([*args, f"out={tmp_path / 'new'}"])
    simulate_command.main([*args[:1], "frames=4", "video=false", f"out={tmp_path / 'new'}"])
    assert json.loads((tmp_path / "new" / "metrics.json").read_text())["n_frames"] == 4
    old = folder_of_mine(tmp_path / "outputs" / "simulate" / "head_on")  # its default, unmarked
    simulate_command.main([*args, f"paths.outputs={tmp_path / 'outputs'}"])
    assert (old / OUTPUT_MARKER).is_file()


def test_eval_writes_over_no_report_dir_it_did_not_write(tmp_path, capsys):
    folder = folder_of_mine(tmp_path / "mine")
    with pytest.raises(SystemExit) as exit_info:
        eval_command.main.__wrapped__(compose_eval(tmp_path, f"report_dir={folder}"))
    assert exit_info.value.code == 2 and capsys.readouterr().err == refusal("report_dir", folder)
    assert [p.name for p in folder.iterdir()] == ["metrics.json"]
    new = tmp_path / "new"
    for report_dir, overwrite in [(folder, "true"), (new, "false")] * 2:
        cfg = compose_eval(tmp_path, f"report_dir={report_dir}", f"overwrite={overwrite}")
        with pytest.raises(EvalError, match="no finished run"):  # the check passed
            evaluate(cfg)
        if not report_dir.exists():  # a failed eval leaves no folder it made; an earlier one's:
            claim_folder(report_dir, "report_dir")
        (report_dir / "report.md").write_text("an earlier report")
    assert not (folder / OUTPUT_MARKER).exists() and (new / OUTPUT_MARKER).is_file()
    assert (new / "report.md").read_text() == "an earlier report"
    folder_of_mine(tmp_path / "report")  # the default report_dir, unmarked: physgnn's own
    with pytest.raises(EvalError, match="no finished run"):
        evaluate(compose_eval(tmp_path))


# --- Ctrl-C and SIGTERM during training -----------------------------------------------------


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_mid_epoch_stops_saves_and_resumes(tiny_dataset, tmp_path, signum):
    budget = [*SHORT, "trainer.max_epochs=2", "datamodule.pairs_per_epoch=16"]  # 4 steps/epoch
    run_dir = tmp_path / "runs" / "stopped"
    handler = signal.getsignal(signum)
    with pytest.raises(TrainingInterrupted, match=f"stopped by {signum.name} at step 2") as stop:
        train(config(tiny_dataset, run_dir, *budget, *signal_at(signum, 2)))
    assert stop.value.exit_code == 128 + signum and signal.getsignal(signum) == handler
    info = read_run_json(run_dir)
    assert info["status"] == "interrupted" and info["error"] == f"stopped by {signum.name}"
    assert info["global_step"] == 2 and info["pairs_seen"] == 8 and info["epochs"] == 0
    last = run_dir / "checkpoints" / "last.ckpt"
    assert info["checkpoints"]["last"] == str(last)
    assert torch.load(last, weights_only=True)["global_step"] == 2  # mid-epoch
    note = f"`runs/stopped`: status interrupted (stopped by {signum.name})"
    assert load_runs(compose_eval(tmp_path), tmp_path) == ([], [note])  # eval lists it
    typo = "model.network.M must be a whole number"  # a typo on restart
    with pytest.raises(ConfigError, match=typo):
        train(config(tiny_dataset, run_dir, *budget, "model.network.M=abc"))
    resumed = train(config(tiny_dataset, run_dir, *budget))  # the same folder: resumes
    assert resumed["status"] == "finished" and resumed["resumed_from"] == str(last)
    assert resumed["global_step"] == 8 and resumed["pairs_seen"] == 32
    # the resumed run's clock goes on from the time its checkpoint carried (the interrupted
    # session's run.json also counts the moments after that save: no order between the two)
    callbacks = torch.load(last, weights_only=True)["callbacks"].values()
    carried = next(state["train_time_s"] for state in callbacks if "train_time_s" in state)
    assert resumed["sessions"] == 2 and resumed["train_time_s"] > carried > 0


def test_a_second_ctrl_c_stops_at_once(tiny_dataset, tmp_path):
    cfg = config(tiny_dataset, tmp_path, *SHORT, *signal_at(signal.SIGINT, 1, times=2))
    with pytest.raises(TrainingInterrupted, match="stopped at once") as stop:
        train(cfg)
    assert stop.value.exit_code == 130
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert read_run_json(tmp_path)["status"] == "interrupted"


# --- one failing job in a sweep ---------------------------------------------------------------


def test_failing_jobs_never_stop_a_sweep(tiny_dataset, tmp_path, monkeypatch, capsys):
    outputs = outputs_of(tiny_dataset)
    sweep = tmp_path / "sweep"
    args = ["-m", "lit.noise.std=abc,1e30,0.01", "data=tiny", f"paths.outputs={outputs}"]
    monkeypatch.setattr(sys, "argv", ["physgnn.train", *args, f"hydra.sweep.dir={sweep}", *SHORT])
    with pytest.raises(SystemExit) as exit_info:
        train_command.main()
    assert exit_info.value.code == 1
    summary = json.loads((sweep / "sweep.json").read_text())
    assert [j["status"] for j in summary["jobs"]] == ["failed", "diverged", "finished"]
    assert summary["jobs"][0]["error"] == "ConfigError: lit.noise.std must be a number, got 'abc'"
    err = capsys.readouterr().err
    assert "error: lit.noise.std must be a number, got 'abc' (this job failed;" in err
    assert err.strip().splitlines()[-1].startswith("error: 2 job(s) of the sweep did not finish")


# --- debug=fast ---------------------------------------------------------------------------------


def test_debug_fast_leaves_nothing_eval_takes_for_a_model(tiny_dataset, tmp_path):
    run_dir = tmp_path / "runs" / "smoke"
    train(config(tiny_dataset, run_dir, "debug=fast", "model.network.hidden=16"))
    assert read_run_json(run_dir)["status"] == "debug" and not list(run_dir.rglob("*.ckpt"))
    assert find_runs(None, tmp_path) == []
    eval_cfg = compose_eval(tmp_path)
    assert load_runs(eval_cfg, tmp_path) == ([], ["`runs/smoke`: status debug"])


def compose_eval(outputs, *overrides):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(
            "eval", overrides=[f"paths.outputs={outputs}", "invariance.rest_frames=4", *overrides]
        )


# --- data-report honours PHYSGNN_OUTPUTS --------------------------------------------------------


def test_data_report_follows_physgnn_outputs_with_the_right_hint(tmp_path, monkeypatch):
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path))
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose("data_report", overrides=["preset=tiny"])
    assert cfg.dataset == f"{tmp_path}/data/tiny"
    hint = "run `make data PRESET=tiny` or `python -m physgnn.generate data=tiny`"
    with pytest.raises(DataReportError, match=f"{tmp_path}/data/tiny not found: {hint}"):
        data_report(cfg)
    make = subprocess.run(
        ["make", "-n", "data-report", "PRESET=tiny"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    assert "-m physgnn.data_report preset=tiny" in make.stdout and "outputs/" not in make.stdout


# --- one line naming the key or the file --------------------------------------------------------


def hydra_args(tiny_dataset, run_dir) -> list[str]:
    return ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"hydra.run.dir={run_dir}"]


def test_resuming_a_missing_or_foreign_checkpoint_is_one_line(
    tiny_dataset, tmp_path, monkeypatch, capsys
):
    monkeypatch.setattr(
        sys,
        "argv",
        ["physgnn.train", *hydra_args(tiny_dataset, tmp_path / "m1"), *SHORT, "model.network.M=1"],
    )
    train_command.main()  # a run with its .hydra/config.yaml
    missing = tmp_path / "none.ckpt"
    code, line = run_main(
        monkeypatch,
        capsys,
        *hydra_args(tiny_dataset, tmp_path / "a"),
        *SHORT,
        f"ckpt_path={missing}",
    )
    assert code == 2 and line.startswith(f"error: ckpt_path={missing}: no such file")
    last = tmp_path / "m1" / "checkpoints" / "last.ckpt"
    code, line = run_main(
        monkeypatch,
        capsys,
        *hydra_args(tiny_dataset, tmp_path / "b"),
        *SHORT,
        "model.network.M=2",
        f"ckpt_path={last}",
    )
    assert code == 2 and line.startswith(f"error: ckpt_path={last} does not fit this model")
    assert "model.network.M is 1 there, 2 here" in line
    assert read_run_json(tmp_path / "b")["status"] == "failed"


@pytest.mark.parametrize("status", ["finished", "truncated", "diverged", "debug"])
def test_a_run_folder_is_never_trained_over(tiny_dataset, tmp_path, status):
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "best-epoch001.ckpt").write_bytes(b"weights")
    (tmp_path / "run.json").write_text(json.dumps({"status": status}))
    with pytest.raises(ConfigError, match=f"run_dir {tmp_path} already holds a {status} run"):
        train(config(tiny_dataset, tmp_path, *SHORT))
    assert read_run_json(tmp_path) == {"status": status}
    assert (tmp_path / "checkpoints" / "best-epoch001.ckpt").read_bytes() == b"weights"


def test_any_command_stopped_by_ctrl_c_is_one_line(capsys):
    def stopped(cfg):
        raise KeyboardInterrupt

    with pytest.raises(SystemExit) as exit_info:
        command("eval", stopped).__wrapped__(OmegaConf.create())
    assert exit_info.value.code == 130
    assert capsys.readouterr().err == "error: eval interrupted (exit code 130)\n"


@pytest.mark.parametrize(
    "override,message",
    [
        ("workers=abc", "workers must be a whole number >= 1 (processes), got 'abc'"),
        ("workers=-1", "workers must be a whole number >= 1 (processes), got -1"),
        (
            "data.scene.side_min=-6",
            "data.scene.side_min must be a number >= 2 (m, an arena's side: the largest "
            "sphere's diameter 2 × radius_max), got -6",
        ),
        ("data.scene.side_max=5", "data.scene.side_max must be a number >= 6 (m, at least"),
        ("data.scene.n_max=1", "data.scene.n_max must be a whole number >= 2 (spheres, at"),
        ("data.scene.h_max=0.5", "data.scene.h_max must be a number >= 1 (m, the highest"),
    ],
)
def test_bad_generate_workers_are_one_line(tmp_path, monkeypatch, capsys, override, message):
    argv = ["physgnn.generate", "data=tiny", f"paths.outputs={tmp_path}", override]
    monkeypatch.setattr(sys, "argv", [*argv, f"hydra.run.dir={tmp_path}/logs"])
    with pytest.raises(SystemExit) as exit_info:
        generate_command.main()
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"error: {message}")
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").iterdir())


@pytest.mark.parametrize(
    "override,message",
    [
        ("model.network.M=abc", "model.network.M must be a whole number, got 'abc'"),
        ("datamodule.batch_size=1.5", "datamodule.batch_size must be a whole number, got 1.5"),
        (
            "lit.scheduler.decay_per_epoch=-1",
            "lit.scheduler.decay_per_epoch must be a number in (0, 1000) (lr x decay_per_epoch^",
        ),
        (
            "trainer.max_epochs=0",
            "trainer.max_epochs must be a whole number >= 1 or -1 or null (-1 or null: no limit), "
            "got 0 (e.g. trainer.max_epochs=10)",
        ),
        ("lit.optimizer.lr=-1", "lit.optimizer.lr must be a number > 0, got -1 (conf/lit/"),
        ("seed=-5", "seed must be a whole number from 0 to 4294967295, got -5 (conf/train.yaml"),
        (
            "trainer.strategy=ddp",
            "trainer.strategy=ddp fails at the first batch without contacts (the network "
            "skips the MLPs a batch lacks): leave trainer.strategy=auto (DDP is chosen for "
            "several devices) or set trainer.strategy=ddp_find_unused_parameters_true",
        ),
        ("data.val_rollout.frames=1", "data.val_rollout.frames must be a whole number >= 2, got 1"),
        (
            "~data.val_rollout",
            "data.val_rollout.trajectories is missing (data=tiny): add val_rollout: "
            "{trajectories: 10, frames: null, horizon: 20} to the preset, as "
            "conf/data/small.yaml has it",
        ),
        (
            "data.val_rollout.horizon=0",
            "data.val_rollout.horizon must be a whole number >= 1, got 0",
        ),
        (  # found at the first rollout validation, after one epoch
            "data.val_rollout.horizon=20",
            "validation trajectory 'traj_00000' has 20 frames, the score needs H + horizon + 1 "
            "= 21: lower callbacks.rollout.horizon=20 (the data preset's val_rollout.horizon)",
        ),
        (
            "callbacks.rollout.n_val_trajectories=0",
            "callbacks.rollout.n_val_trajectories must be a whole number >= 1, got 0",
        ),
        (
            "~callbacks.rollout",
            "callbacks.checkpoint.monitor=val/rollout_score is logged by the "
            "rollout callback only: keep callbacks.rollout, or set callbacks.checkpoint.monitor="
            "val/loss",
        ),
    ],
)
def test_config_mistakes_name_the_key_and_are_recorded(
    tiny_dataset, tmp_path, monkeypatch, capsys, override, message
):
    code, line = run_main(monkeypatch, capsys, *hydra_args(tiny_dataset, tmp_path), override)
    assert code == 2 and line.startswith(f"error: {message}")
    info = read_run_json(tmp_path)  # the run folder says what went wrong ...
    assert info["status"] == "failed" and message in info["error"]
    assert message in (tmp_path / "train.log").read_text()  # ... and so does its log


def test_a_flat_recipe_key_is_one_line_before_anything_is_written(
    tiny_dataset, tmp_path, monkeypatch, capsys
):
    args = hydra_args(tiny_dataset, tmp_path)
    code, line = run_main(monkeypatch, capsys, *args, "lit.noise_std=0.01")
    assert code == 2
    assert line == "error: lit.noise_std is now lit.noise.std: write lit.noise.std=0.01"
    assert not (tmp_path / "run.json").exists()


def test_physgnn_outputs_naming_a_file_is_one_line(tmp_path, monkeypatch, capsys):
    outputs = tmp_path / "outputs"
    outputs.write_text("not a folder")
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(outputs))
    code, line = run_main(monkeypatch, capsys, "data=tiny", *SHORT)
    assert code == 2 and line == (
        f"error: PHYSGNN_OUTPUTS={outputs} is a file: set it to a folder (physgnn writes its "
        "data, runs and reports there), or unset it to write into ./outputs"
    )
    assert outputs.read_text() == "not a folder"


@pytest.mark.parametrize(
    "bad,problem",
    [
        ('{"key": "a", "seed": 0, "bud', "not a JSON line (Unterminated string starting at)"),
        ('{"seed": 0, "budget": {}}', "not a run record (KeyError: 'key')"),
        (
            "[1, 2]",
            "not a run record (TypeError: list indices must be integers or slices, not str)",
        ),
    ],
)
def test_a_corrupt_registry_line_is_one_line(tmp_path, capsys, bad, problem):
    registry = tmp_path / "registry.jsonl"
    append_record(registry, {"key": "a", "seed": 0, "budget": {"steps": 3}, "status": "finished"})
    registry.write_text(registry.read_text() + bad + "\n")
    with pytest.raises(SystemExit) as exit_info:
        command("study", lambda cfg: read_registry(registry)).__wrapped__(OmegaConf.create())
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        f"error: {registry}:2: {problem}: repair or delete that line (one JSON record per run; a "
        "run whose line is deleted is trained again by make study)\n"
    )


def test_zero_std_in_stats_names_the_file_and_key(tiny_dataset, tmp_path, monkeypatch, capsys):
    outputs = tmp_path / "outputs"
    data = copy_dataset(tiny_dataset, outputs)
    stats = json.loads((data / "stats.json").read_text())
    stats["vel"]["std"][0] = 0.0
    (data / "stats.json").write_text(json.dumps(stats))
    args = ["data=tiny", f"paths.outputs={outputs}", f"hydra.run.dir={tmp_path / 'run'}"]
    code, line = run_main(monkeypatch, capsys, *args, *SHORT)
    assert code == 2
    assert line.startswith(f"error: {data / 'stats.json'}: vel.std must be positive and finite")
    # outputs elsewhere than make data's: the fix names the folder itself
    assert line.endswith(f"`python -m physgnn.generate data=tiny data.dir={data} overwrite=true`)")


def test_an_exploding_model_names_no_checkpoint_folder_that_is_not_there(tiny_dataset, tmp_path):
    with pytest.raises(Exception, match="the model exploded.*; no checkpoint was saved$"):
        train(config(tiny_dataset, tmp_path, *SHORT, "lit.noise.std=1e30"))
    assert not (tmp_path / "checkpoints").exists()


def test_a_resume_with_nothing_left_to_train_says_so(tiny_dataset, tmp_path):
    first = train(config(tiny_dataset, tmp_path / "a", *SHORT))
    last = first["checkpoints"]["last"]
    with pytest.raises(ConfigError, match="nothing to train: .* trainer.max_epochs=1 \\(step 2\\)"):
        train(config(tiny_dataset, tmp_path / "b", *SHORT, f"ckpt_path={last}"))


# --- the run's own train.log -------------------------------------------------------------------


def test_run_dir_gets_the_log_of_every_session(tiny_dataset, tmp_path, monkeypatch, capsys):
    run_dir, hydra_dir = tmp_path / "run", tmp_path / "hydra"
    args = [
        "data=tiny",
        f"paths.outputs={outputs_of(tiny_dataset)}",
        f"run_dir={run_dir}",
        *SHORT,
        *signal_at(signal.SIGINT, 1),
    ]  # a resume takes the same overrides
    code, line = run_main(monkeypatch, capsys, *args, f"hydra.run.dir={hydra_dir}/1")
    assert code == 130 and line.endswith(
        f"Resume: python -m physgnn.train run_dir={run_dir} (same overrides)"
    )
    first = (run_dir / "train.log").read_text()  # a fresh run given its folder
    assert f"training baseline in {run_dir}\n" in first and "interrupted (stopped by" in first
    monkeypatch.setattr(sys, "argv", ["physgnn.train", *args, f"hydra.run.dir={hydra_dir}/2"])
    train_command.main()  # the resume command
    log = (run_dir / "train.log").read_text()
    assert log.startswith(first) and f"resuming from {run_dir}/checkpoints/last.ckpt" in log
    assert log.rstrip().endswith("finished after 2 steps")
    assert (hydra_dir / "2" / "train.log").read_text() == ""  # nothing in Hydra's own folder


# --- a run folder in use -----------------------------------------------------------------------


def running_record(run_dir: Path, pid: int) -> dict:
    info = {
        "status": "running",
        "pid": pid,
        "host": socket.gethostname(),
        "started": "2026-01-02T03:04:05",
    }
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run.json").write_text(json.dumps(info))
    return info


def test_a_run_folder_in_use_is_refused_in_one_line(tiny_dataset, tmp_path, monkeypatch, capsys):
    run_dir = tmp_path / "run"
    holder = subprocess.Popen(["sleep", "60"])
    try:
        info = running_record(run_dir, holder.pid)
        args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={run_dir}"]
        code, line = run_main(monkeypatch, capsys, *args, f"hydra.run.dir={tmp_path / 'h'}")
    finally:
        holder.kill()
        holder.wait()
    assert code == 2 and line == (
        f"error: run_dir {run_dir} is in use: a training started 2026-01-02T03:04:05 runs "
        f"there (pid {holder.pid} on {info['host']}): wait for it to end, stop it (kill "
        f"{holder.pid}: it saves last.ckpt, then train again there to resume), or choose "
        "another run_dir"
    )
    assert read_run_json(run_dir) == info and sorted(p.name for p in run_dir.iterdir()) == [
        "run.json"
    ]


def test_a_running_record_of_a_dead_process_is_taken_over(tiny_dataset, tmp_path):
    dead = subprocess.Popen(["true"])
    dead.wait()
    running_record(tmp_path, dead.pid)
    assert train(config(tiny_dataset, tmp_path, *SHORT))["status"] == "finished"


# --- a full disk ------------------------------------------------------------------------------


def test_a_full_disk_keeps_the_last_good_checkpoint_and_says_failed(
    tiny_dataset, tmp_path, monkeypatch
):
    save = torch.save

    def full_disk(obj, f, *args, **kwargs):
        """The epoch-2 save to a file writes half of it, then the disk is full."""
        if isinstance(f, str | Path) and obj.get("global_step", 0) > 2:
            Path(f).write_bytes(b"half a checkpoint")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return save(obj, f, *args, **kwargs)

    monkeypatch.setattr(torch, "save", full_disk)
    with pytest.raises(OSError, match="No space left on device"):
        train(config(tiny_dataset, tmp_path, *SHORT, "trainer.max_epochs=2"))
    assert torch.load(tmp_path / "checkpoints" / "last.ckpt", weights_only=True)["global_step"] == 2
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir())[-1] == "last.ckpt"
    assert not list(tmp_path.rglob("*.tmp*"))
    info = read_run_json(tmp_path)
    assert info["status"] == "failed" and "No space left on device" in info["error"]


# --- killed in a subprocess ----------------------------------------------------------------------


def interrupt(proc: subprocess.Popen, signum: int) -> None:
    """Ctrl-C reaches the whole process group (workers too); ``kill`` one process."""
    if signum == signal.SIGINT:
        os.killpg(proc.pid, signum)
    else:
        proc.send_signal(signum)


def children(pid: int) -> list[int]:
    found = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True)
    return [int(p) for p in found.stdout.split()]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_killing_generate_is_one_line_and_leaves_the_dataset(tiny_dataset, tmp_path, signum):
    data = copy_dataset(tiny_dataset, tmp_path)
    before = {p.name: p.read_bytes() for p in data.iterdir()}
    proc = start(
        [
            "physgnn.generate",
            "data=tiny",
            f"paths.outputs={tmp_path}",
            "workers=2",
            "overwrite=true",
            "data.splits.train=400",
            "progress=false",
            f"hydra.run.dir={tmp_path}/logs",
        ]
    )
    wait_for(data.with_name("tiny.partial") / DATASET_MARKER, proc)
    time.sleep(1.0)  # the workers are simulating
    workers = children(proc.pid)
    assert len(workers) >= 2
    interrupt(proc, signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signum
    assert err.strip().splitlines() == [
        f"error: generation stopped by {signum.name}: {data} was left as it was"
    ]
    assert {p.name: p.read_bytes() for p in data.iterdir()} == before
    assert sorted(p.name for p in data.parent.iterdir()) == ["tiny"]  # no staging left
    assert not any(Path(f"/proc/{pid}").exists() for pid in workers)


def test_killing_training_saves_it_and_it_resumes(tiny_dataset, tmp_path):
    run_dir = tmp_path / "run"
    budget = ["trainer.max_epochs=1", "datamodule.pairs_per_epoch=4000"]
    proc = start(
        [
            "physgnn.train",
            "data=tiny",
            f"paths.outputs={outputs_of(tiny_dataset)}",
            f"hydra.run.dir={run_dir}",
            *SHORT,
            *budget,
        ]
    )
    wait_for(run_dir / "run.json", proc)
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143
    line = err.strip().splitlines()[-1]
    assert line.startswith("error: training stopped by SIGTERM at step")
    assert line.endswith(f"Resume: python -m physgnn.train run_dir={run_dir} (same overrides)")
    info = read_run_json(run_dir)
    assert info["status"] == "interrupted" and 1 <= info["global_step"] < 1000
    ckpt = torch.load(info["checkpoints"]["last"], weights_only=True)
    assert ckpt["global_step"] == info["global_step"]
    steps = info["global_step"] + 2
    resumed = train(config(tiny_dataset, run_dir, *SHORT, *budget, f"+trainer.max_steps={steps}"))
    assert resumed["status"] == "finished" and resumed["sessions"] == 2
    assert resumed["global_step"] == steps and resumed["pairs_seen"] == 4 * steps


# --- signals owned by a job scheduler -----------------------------------------------------------


def test_a_schedulers_handlers_are_kept_and_its_preemption_signal_chained(monkeypatch):
    """Under submitit, SIGTERM stays submitit's (it ignores it) and SIGUSR2 stops training
    cleanly, then goes on to submitit's handler (which requeues the job)."""
    monkeypatch.setenv("SUBMITIT_EXECUTOR", "slurm")
    calls = []

    def bypass(signum, frame):
        calls.append(("bypass", signum))

    def requeue(signum, frame):
        calls.append(("requeue", signum))

    before = {
        s: signal.signal(s, h) for s, h in ((signal.SIGTERM, bypass), (signal.SIGUSR2, requeue))
    }
    try:
        stop = StopOnSignal()
        stop.install()
        assert signal.getsignal(signal.SIGTERM) is bypass
        with sigterm_interrupts():  # the CLI's: it leaves a scheduler's SIGTERM alone too
            assert signal.getsignal(signal.SIGTERM) is bypass
        os.kill(os.getpid(), signal.SIGUSR2)
        assert stop.signum == signal.SIGUSR2 and calls == []
        stop.restore()
        assert signal.getsignal(signal.SIGUSR2) is requeue
        stop.chain()
        assert calls == [("requeue", signal.SIGUSR2)]
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)


def test_sigterm_is_an_interrupt_where_nobody_handles_it():
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    with pytest.raises(KeyboardInterrupt) as stopped, sigterm_interrupts():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(1)  # the handler runs before this returns
    assert interrupt_signal(stopped.value) == signal.SIGTERM
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL


def test_paths_in_committed_files_are_relative_to_the_working_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert portable(tmp_path / "outputs" / "study" / "seed0") == "outputs/study/seed0"
    assert portable("outputs/study") == "outputs/study"
    assert portable("/elsewhere/study") == "/elsewhere/study"  # not below it: unchanged
