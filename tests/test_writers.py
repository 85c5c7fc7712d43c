"""Writers and folders: two writers into one folder, an interrupted writer, a folder holding
the user's files, a resume with other overrides. Each either refused in one line or made safe,
and nothing of the user's replaced."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import h5py
import pytest
from trainkit import SHORT, config, outputs_of, run_main

from physgnn import CONF_DIR
from physgnn import eval as eval_command
from physgnn import simulate as simulate_command
from physgnn import train as train_command
from physgnn.errors import ConfigError, PhysgnnError
from physgnn.evaluation import simulate as simulate_module
from physgnn.files import OUTPUT_MARKER, staged_outputs
from physgnn.locks import InUseError
from physgnn.training.export import export_run
from physgnn.training.runs import PRETRAINED_DIR, read_run_json
from physgnn.training.train import train

ROOT = Path(__file__).resolve().parents[1]
SCENES = Path(CONF_DIR) / "scene"


@pytest.fixture
def live_pid():
    """The pid of a live process of this host (not this one): a lock's holder."""
    holder = subprocess.Popen(["sleep", "60"])
    yield holder.pid
    holder.kill()
    holder.wait()


def hold_lock(folder: Path, pid: int) -> Path:
    lock = folder.with_name(folder.name + ".lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    lock.write_text(json.dumps({"pid": pid, "host": socket.gethostname(), "since": "then"}))
    return lock


# --- one writer at a time, whole outputs -------------------------------------------------------


def test_staged_outputs_replace_the_previous_whole_or_not_at_all(tmp_path):
    folder = tmp_path / "out"
    with staged_outputs(folder, "out", ["a.txt", "b.txt"]) as staging:
        (staging / "a.txt").write_text("first")
        (staging / "b.txt").write_text("first")
    (folder / "mine.txt").write_text("the user's")
    with pytest.raises(KeyboardInterrupt), staged_outputs(folder, "out", ["a.txt", "b.txt"]) as s:
        (s / "a.txt").write_text("second")
        raise KeyboardInterrupt
    assert (folder / "a.txt").read_text() == "first" and (folder / "b.txt").exists()
    with staged_outputs(folder, "out", ["a.txt", "b.txt"]) as staging:
        (staging / "a.txt").write_text("third")  # no b.txt this time: the old one goes
    assert sorted(p.name for p in folder.iterdir()) == ["a.txt", "mine.txt"]
    assert (folder / "a.txt").read_text() == "third"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no lock, no staging left


def test_a_second_writer_is_refused_in_one_line(tmp_path, live_pid):
    folder = tmp_path / "out"
    lock = hold_lock(folder, live_pid)
    with pytest.raises(InUseError, match=f"out {folder} is in use: pid {live_pid} on "):
        with staged_outputs(folder, "out", ["a.txt"]):
            pass
    assert lock.exists() and not folder.exists()


def test_two_evals_into_one_report_dir_the_second_is_refused(tmp_path, live_pid, capsys):
    report_dir = tmp_path / "report"
    report_dir.mkdir()
    (report_dir / OUTPUT_MARKER).write_text("{}")
    (report_dir / "report.md").write_text("the first eval's")
    hold_lock(report_dir, live_pid)
    cfg = eval_config(tmp_path, f"report_dir={report_dir}")
    with pytest.raises(SystemExit) as exit_info:
        eval_command.main.__wrapped__(cfg)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1
    assert err.startswith(f"error: report_dir {report_dir} is in use: pid {live_pid}")
    assert err.rstrip().endswith(
        "wait for it to end, or choose another report_dir; if pid "
        f"{live_pid} is not a physgnn process (its pid reused), remove the lock file "
        f"{report_dir}.lock"
    )
    assert (report_dir / "report.md").read_text() == "the first eval's"


def eval_config(outputs: Path, *overrides):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(
            "eval", overrides=[f"paths.outputs={outputs}", "invariance.rest_frames=4", *overrides]
        )


# --- simulate: one scene per out, whole ---------------------------------------------------------


def simulate(out: Path, scene: str, *extra: str) -> None:
    simulate_command.main(
        [f"scene_file={SCENES / scene}", "frames=3", "video=false", f"out={out}", *extra]
    )


def scene_in(out: Path) -> tuple[str, str]:
    """The scene named by metrics.json and by simulate.h5."""
    with h5py.File(out / "simulate.h5") as f:
        h5_scene = f["truth"].attrs["scene"]
    return json.loads((out / "metrics.json").read_text())["scene"], h5_scene


def test_simulate_interrupted_or_run_again_never_mixes_two_scenes(tmp_path, monkeypatch):
    out = tmp_path / "out"
    simulate(out, "head_on.yaml")
    (out / "video.gif").write_bytes(b"head_on's video")  # as a run with video=true leaves it

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(simulate_module, "scene_metrics", interrupted)
        with pytest.raises(SystemExit) as exit_info:
            simulate(out, "throw.yaml")
    assert exit_info.value.code == 130
    assert scene_in(out) == ("head_on", "head_on") and (out / "video.gif").exists()
    simulate(out, "throw.yaml")
    assert scene_in(out) == ("throw", "throw") and not (out / "video.gif").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_two_simulates_into_one_out_the_second_is_refused(tmp_path, live_pid, capsys):
    out = tmp_path / "out"
    hold_lock(out, live_pid)
    with pytest.raises(SystemExit) as exit_info:
        simulate(out, "head_on.yaml")
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1
    assert err.startswith(f"error: out {out} is in use: pid {live_pid}")


# --- training and shipping never replace the user's run.json ------------------------------------


def test_train_refuses_a_run_dir_holding_the_users_run_json(tiny_dataset, tmp_path):
    (tmp_path / "run.json").write_text('{"my": "notes"}')
    with pytest.raises(ConfigError, match=f"run_dir {tmp_path} holds a run.json that physgnn"):
        train(config(tiny_dataset, tmp_path, *SHORT))
    assert (tmp_path / "run.json").read_text() == '{"my": "notes"}'


def test_make_ship_without_run_is_refused_and_the_package_untouched():
    before = (PRETRAINED_DIR / "run.json").read_bytes()
    done = subprocess.run(["make", "-s", "ship"], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode != 0
    assert done.stderr.startswith("error: make ship needs RUN=<a finished run folder>")
    with pytest.raises(PhysgnnError, match="RUN_DIR and OUT_DIR are the same folder"):
        export_run(PRETRAINED_DIR, PRETRAINED_DIR)
    assert (PRETRAINED_DIR / "run.json").read_bytes() == before


def test_a_resume_with_other_overrides_is_refused(tiny_dataset, tmp_path, monkeypatch, capsys):
    run_dir = tmp_path / "run"
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={run_dir}", *SHORT]
    monkeypatch.setattr(sys, "argv", ["physgnn.train", *args])
    train_command.main()
    info = read_run_json(run_dir) | {"status": "interrupted"}  # as a Ctrl-C leaves it
    (run_dir / "run.json").write_text(json.dumps(info))
    hydra_overrides = (run_dir / ".hydra" / "overrides.yaml").read_text()
    code, line = run_main(monkeypatch, capsys, *args, "lit.optimizer.lr=0.05")
    assert code == 2 and line.startswith(
        f"error: run_dir {run_dir} resumes a run started with other overrides (missing: none; "
        "new: lit.optimizer.lr=0.05): resume with exactly "
    )
    assert read_run_json(run_dir) == info
    assert (run_dir / ".hydra" / "overrides.yaml").read_text() == hydra_overrides
