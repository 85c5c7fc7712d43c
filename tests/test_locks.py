"""Exclusive writers: a dataset being generated is locked; a second writer gets one line naming
the holder, and the lock of a dead process is taken over."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time

import pytest
from processes import start, wait_for

import physgnn.generate as generate_command
import physgnn.train as train_command
from physgnn import locks
from physgnn.evaluation.runs import EvalError, find_runs
from physgnn.locks import InUseError, exclusive
from physgnn.training.claim import claim_run_dir, release


def dead_pid() -> int:
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def write_lock(path, pid: int, host: str | None = None) -> None:
    holder = {"pid": pid, "host": host or socket.gethostname(), "since": "2026-11-23T10:00:00"}
    path.write_text(json.dumps(holder))


def test_a_live_holder_is_named_and_its_lock_kept(tmp_path):
    lock = tmp_path / "data.lock"
    sleeper = subprocess.Popen(["sleep", "30"])
    try:
        write_lock(lock, sleeper.pid)
        with pytest.raises(InUseError) as err, exclusive(lock, "data.dir X", "wait for it"):
            pass
        message = str(err.value)
        assert "\n" not in message and f"pid {sleeper.pid} on {socket.gethostname()}" in message
        assert "since 2026-11-23T10:00:00" in message and "touched 0 s ago): wait for it" in message
        # the pid may be an unrelated process that took a dead holder's number
        assert message.endswith(
            f"; if pid {sleeper.pid} is not a physgnn process (its pid reused), remove the lock "
            f"file {lock}"
        )
        assert json.loads(lock.read_text())["pid"] == sleeper.pid
    finally:
        sleeper.kill()


@pytest.mark.parametrize("stale", ["dead", "unreadable"])
def test_a_dead_or_unreadable_lock_is_taken_over_and_released(tmp_path, stale):
    lock = tmp_path / "data.lock"
    if stale == "dead":
        write_lock(lock, dead_pid())
    else:
        lock.write_text("")
    with exclusive(lock, "data.dir X", "wait"):
        assert json.loads(lock.read_text())["pid"] == os.getpid()
    assert not lock.exists()


def test_a_lock_of_another_host_is_refused_with_the_way_to_free_it(tmp_path):
    lock = tmp_path / "data.lock"
    write_lock(lock, 12345, host="elsewhere")
    with pytest.raises(InUseError, match=f"remove {lock} if that process is gone"):
        with exclusive(lock, "data.dir X", "wait"):
            pass


def test_a_fresh_lock_of_another_host_names_its_holder_age_and_the_way_to_free_it(tmp_path):
    lock = tmp_path / "run.lock"
    write_lock(lock, 12345, host="otherhost")
    then = time.time() - 40
    os.utime(lock, (then, then))
    with pytest.raises(InUseError) as err, exclusive(lock, "run_dir X", "wait"):
        pass
    assert str(err.value) == (
        f"run_dir X is in use: pid 12345 on otherhost writes there since 2026-11-23T10:00:00 "
        f"(lock {lock}, touched 40 s ago): wait; remove {lock} if that process is gone (a lock "
        "of another host untouched for 10 min is taken over: its holder touches it every 30 s)"
    )
    assert json.loads(lock.read_text())["host"] == "otherhost"


def test_a_lost_nodes_lock_is_taken_over_by_a_requeued_training(tmp_path, capsys):
    """A lock of another host untouched past locks.LOCK_STALE_S: its node is gone."""
    run_dir = tmp_path / "X"
    lock = tmp_path / "X.lock"
    write_lock(lock, 12345, host="otherhost")
    then = time.time() - 3600
    os.utime(lock, (then, then))
    try:
        assert claim_run_dir(run_dir) == lock
        assert json.loads(lock.read_text())["pid"] == os.getpid()
    finally:
        release()
    assert not lock.exists()
    assert capsys.readouterr().err == (
        f"warning: run_dir {run_dir}: taking over the lock {lock} of pid 12345 on otherhost, "
        "untouched for 60 min (a running holder touches it every 30 s: its node is gone)\n"
    )


def test_the_holder_touches_its_lock_while_it_runs(tmp_path, monkeypatch):
    monkeypatch.setattr(locks, "LOCK_HEARTBEAT_S", 0.02)
    lock = tmp_path / "data.lock"
    with exclusive(lock, "data.dir X", "wait"):
        then = time.time() - 3600
        os.utime(lock, (then, then))
        deadline = time.time() + 10
        while lock.stat().st_mtime < time.time() - 60 and time.time() < deadline:
            time.sleep(0.02)
        assert lock.stat().st_mtime > time.time() - 60
    assert not lock.exists()


def test_two_generates_into_one_folder_one_writes_the_other_is_refused(
    tmp_path, monkeypatch, capsys
):
    """The first a child process, the second this one (the command as its console runs it)."""
    outputs = tmp_path / "outputs"
    common = ["data=tiny", f"paths.outputs={outputs}", "progress=false", "workers=1"]
    first = start(
        ["physgnn.generate", *common, "data.splits.train=400", f"hydra.run.dir={tmp_path}/a"]
    )
    lock = outputs / "data" / "tiny.lock"
    wait_for(lock, first)
    argv = ["physgnn.generate", *common, "data.seed=7", f"hydra.run.dir={tmp_path}/b"]
    monkeypatch.setattr(sys, "argv", argv)
    try:
        with pytest.raises(SystemExit) as exit_info:
            generate_command.main()
    finally:
        first.send_signal(signal.SIGTERM)
        first.communicate(timeout=60)
    lines = capsys.readouterr().err.strip().splitlines()
    assert exit_info.value.code == 2 and len(lines) == 1, lines
    assert lines[0].startswith(f"error: data.dir {outputs / 'data' / 'tiny'} is in use: ")
    assert f"pid {first.pid} on {socket.gethostname()}" in lines[0]
    assert not lock.exists()  # the first released it when it stopped


def test_evaluating_a_run_still_training_is_refused_in_one_line(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    trainer = subprocess.Popen(["sleep", "30"])  # stands for the training process
    info = {
        "status": "running",
        "pid": trainer.pid,
        "host": socket.gethostname(),
        "started": "2026-11-23T10:00:00",
    }
    (run / "run.json").write_text(json.dumps(info))
    try:
        with pytest.raises(EvalError) as err:
            find_runs(str(run), tmp_path)
    finally:
        trainer.kill()
    assert f"is still training (pid {trainer.pid} on {socket.gethostname()}" in str(err.value)
    assert "evaluate it when it has finished" in str(err.value) and "\n" not in str(err.value)


def test_a_run_dir_leaves_no_stray_hydra_folder(tiny_dataset, tmp_path, monkeypatch):
    outputs = tmp_path / "outputs"
    shutil.copytree(tiny_dataset, outputs / "data" / "tiny")
    run_dir = tmp_path / "run"
    args = [
        "data=tiny",
        f"paths.outputs={outputs}",
        f"run_dir={run_dir}",
        "model.network.hidden=8",
        "model.network.M=1",
        "trainer.max_epochs=1",
        "datamodule.pairs_per_epoch=8",
        "trainer.enable_progress_bar=false",
    ]
    monkeypatch.setattr(sys, "argv", ["physgnn.train", *args])
    train_command.main()
    assert sorted(p.name for p in outputs.iterdir()) == ["data"]  # no runs/<experiment>/<now>/
    assert (run_dir / ".hydra" / "config.yaml").is_file() and (run_dir / "train.log").stat().st_size
