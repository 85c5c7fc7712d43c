"""Command-line faults: a generate sweep whose jobs fail exits non-zero, a second training
into a run_dir in use leaves its files alone, and the console script's own lines."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from lightning.fabric.strategies.launchers import subprocess_script
from trainkit import SHORT, outputs_of, run_main

import physgnn
import physgnn.__main__ as console_module
from physgnn import generate as generate_command
from physgnn import train as train_command
from physgnn.__main__ import main as console
from physgnn.files import OUTPUT_MARKER


def test_a_generate_sweep_whose_jobs_fail_exits_1_naming_them(tmp_path, monkeypatch, capsys):
    sweep = tmp_path / "sweep"
    args = [
        "-m",
        "data=tiny",
        f"paths.outputs={tmp_path}",
        "workers=1",
        "progress=false",
        "shard=range(0,2)",
        f"hydra.sweep.dir={sweep}",
    ]
    monkeypatch.setattr(sys, "argv", ["physgnn.generate", *args])
    with pytest.raises(SystemExit) as exit_info:
        generate_command.main()
    assert exit_info.value.code == 1
    lines = capsys.readouterr().err.strip().splitlines()
    why = "needs num_shards=N, the number of shards in all"
    assert lines[-3:] == [
        f"  job 0: shard=0 {why}",
        f"  job 1: shard=1 {why}",
        f"error: 2 job(s) of the sweep failed (their errors above; logs in {sweep})",
    ]
    assert not (tmp_path / "data").exists()


def hydra_files(run_dir) -> dict:
    return {p.name: p.read_bytes() for p in (run_dir / ".hydra").iterdir()}


def test_a_training_into_a_run_dir_in_use_rewrites_none_of_its_files(
    tiny_dataset, tmp_path, monkeypatch, capsys
):
    """The first training (a live process holding the run folder, started the same second)
    keeps its .hydra/config.yaml and overrides.yaml: the second is refused before Hydra
    writes them."""
    run_dir = tmp_path / "run"
    (run_dir / ".hydra").mkdir(parents=True)
    (run_dir / ".hydra" / "config.yaml").write_text("model: {network: {M: 1}}\n")
    (run_dir / ".hydra" / "overrides.yaml").write_text("- model.network.M=1\n")
    before = hydra_files(run_dir)
    first = subprocess.Popen(["sleep", "30"])  # stands for the first training
    holder = {"pid": first.pid, "host": socket.gethostname(), "since": "2026-11-26T10:00:00"}
    (tmp_path / "run.lock").write_text(json.dumps(holder))
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={run_dir}"]
    try:
        code, line = run_main(monkeypatch, capsys, *args, *SHORT, "model.network.M=2")
    finally:
        first.kill()
        first.wait()
    assert code == 2 and line.startswith(
        f"error: run_dir {run_dir} is in use: pid {first.pid} on {socket.gethostname()} writes "
        "there since 2026-11-26T10:00:00"
    )
    assert hydra_files(run_dir) == before and sorted(p.name for p in run_dir.iterdir()) == [
        ".hydra"
    ]


def test_a_training_into_a_finished_run_rewrites_none_of_its_files(
    tiny_run, tiny_dataset, tmp_path, monkeypatch, capsys
):
    run_dir = tmp_path / "run"
    shutil.copytree(tiny_run, run_dir)
    before = hydra_files(run_dir)
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={run_dir}"]
    code, line = run_main(monkeypatch, capsys, *args, *SHORT, "model.network.M=2")
    assert code == 2 and line.startswith(
        f"error: run_dir {run_dir} already holds a finished run with checkpoints and is never "
        "trained over"
    )
    assert hydra_files(run_dir) == before and not (tmp_path / "run.lock").exists()


def test_ship_into_a_users_folder_advises_no_switch_it_lacks(tiny_run, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(SystemExit) as exit_info:
        console(["ship", str(tiny_run), str(out)])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        f"error: OUT_DIR {out} is a folder with files that physgnn did not write (no "
        f"{OUTPUT_MARKER}): choose another OUT_DIR\n"
    )
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


@pytest.mark.parametrize("flag", ["--version", "-V"])
def test_the_console_script_says_its_version(flag, capsys):
    assert console([flag]) == 0
    assert capsys.readouterr().out == f"physgnn {physgnn.__version__}\n"


def test_an_unquoted_non_ascii_path_gives_the_quoting_fix(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        console(["simulate", f"scene_file={tmp_path}/été/s.yaml", "video=false"])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        f"error: scene_file: Hydra reads a value with 'é' only in quotes: write "
        f"'scene_file=\"{tmp_path}/été/s.yaml\"' (the shell's quotes around Hydra's)\n"
    )
    scene = tmp_path / "été" / "s.yaml"
    scene.parent.mkdir()
    scene.write_text("frames: 3\nspheres:\n  - {radius: 0.5, position: [0, 0, 1]}\n")
    out = tmp_path / "out"
    console(["simulate", f'scene_file="{scene}"', "video=false", f"out={out}"])
    assert (out / "simulate.h5").is_file()


def test_a_run_records_which_dataset_it_trained_on(tiny_run, tiny_dataset):
    digest = hashlib.sha256((tiny_dataset / "stats.json").read_bytes())
    for name in ("stats.json", "train.h5", "val.h5"):
        digest.update(f"{name}:{(tiny_dataset / name).stat().st_size};".encode())
    recorded = json.loads((tiny_run / "run.json").read_text())["dataset"]
    assert recorded == {"preset": "tiny", "dir": str(tiny_dataset), "sha256": digest.hexdigest()}


def test_ddps_other_processes_rerun_the_command_not_the_console_script(monkeypatch):
    """Lightning starts DDP's other processes from __main__'s module and sys.argv[1:]: through
    ``physgnn train`` (a console script: no module) and ``python -m physgnn train`` alike, that
    is ``python -m physgnn.train <the same overrides>``."""
    monkeypatch.setattr(train_command, "main", subprocess_script._basic_subprocess_cmd)
    main_module = sys.modules["__main__"]
    for spec in (None, main_module.__spec__):  # the console script; python -m physgnn
        monkeypatch.setattr(main_module, "__spec__", spec)
        command = console(["train", "trainer=ddp_cpu", "data=tiny"])
        assert command == [sys.executable, "-m", "physgnn.train", "trainer=ddp_cpu", "data=tiny"]
        assert main_module.__spec__ is spec  # as it was, after the command
    assert console_module.COMMANDS["train"][0] == "physgnn.train"


@pytest.mark.slow
def test_ddp_on_two_gloo_processes_through_the_console_script(tiny_dataset, tmp_path):
    run_dir = tmp_path / "run"
    script = Path(sys.executable).parent / "physgnn"
    cmd = [
        str(script),
        "train",
        "trainer=ddp_cpu",
        "trainer.devices=2",
        "data=tiny",
        f"paths.outputs={outputs_of(tiny_dataset)}",
        f"run_dir={run_dir}",
        *SHORT,
        "datamodule.pairs_per_epoch=16",
    ]
    env = {
        **os.environ,
        "PYTHONPATH": str(Path(__file__).resolve().parents[1]),
        "OMP_NUM_THREADS": "1",
    }
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    info = json.loads((run_dir / "run.json").read_text())
    assert info["status"] == "finished" and info["global_step"] == 2  # 16 pairs: 2 x 2 x 4
    log = (run_dir / "train.log").read_text() + done.stderr
    assert "Initializing distributed: GLOBAL_RANK: 1, MEMBER: 2/2" in log


def test_simulate_refuses_a_run_still_training(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    trainer = subprocess.Popen(["sleep", "30"])  # stands for the training process
    info = {
        "status": "running",
        "pid": trainer.pid,
        "host": socket.gethostname(),
        "started": "2026-11-26T10:00:00",
    }
    (run / "run.json").write_text(json.dumps(info))
    try:
        with pytest.raises(SystemExit) as exit_info:
            console(
                [
                    "simulate",
                    "scene=head_on",
                    f"run={run}",
                    "video=false",
                    "frames=5",
                    f"out={tmp_path / 'out'}",
                ]
            )
    finally:
        trainer.kill()
        trainer.wait()
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"error: run {run} is still training (pid {trainer.pid} on {socket.gethostname()}, "
        "started 2026-11-26T10:00:00): its checkpoints are mid-run; load it when it has finished"
    )
