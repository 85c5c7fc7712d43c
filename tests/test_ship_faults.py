"""``make ship`` under fault: a run not finished is refused as eval refuses it, and a package
that cannot be written whole (a full disk) leaves the earlier package as it was."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest
import torch
from conftest import mounted_tmpfs

import physgnn.training.export as export
from physgnn.training.export import ShipError, export_run, main
from physgnn.training.runs import RunError


def fake_run(folder: Path, status: str = "finished", weights: int = 1000, step: int = 7) -> Path:
    """A run folder as training leaves it, with a checkpoint of ``weights`` floats."""
    (folder / ".hydra").mkdir(parents=True)
    (folder / ".hydra" / "config.yaml").write_text("model: {}\n")
    (folder / "checkpoints").mkdir()
    state = {"simulator.w": torch.arange(weights, dtype=torch.float32), "lit.x": torch.ones(3)}
    torch.save({"state_dict": state, "global_step": step}, folder / "checkpoints" / "last.ckpt")
    info = {"status": status, "experiment": "baseline", "seed": 0}
    if status == "running":
        info |= {"pid": 2**22 + 17, "host": "somewhere", "started": "2026-01-01T00:00:00"}
    (folder / "run.json").write_text(json.dumps(info))
    return folder


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("status", ["interrupted", "failed", "diverged", "debug", "running"])
def test_a_run_that_has_not_finished_is_refused_as_eval_refuses_it(tmp_path, status, capsys):
    run = fake_run(tmp_path / "run", status)
    assert main([str(run), str(tmp_path / "O")]) == 2
    resume = " (train again there to resume it)" if status in ("interrupted", "running") else ""
    assert capsys.readouterr().err == (
        f"error: run {run} has not finished (run.json status is '{status}'): ship it when it "
        f"has finished{resume}\n"
    )
    assert not (tmp_path / "O").exists()


def test_a_run_still_training_is_refused_naming_its_process(tmp_path):
    run = fake_run(tmp_path / "run", "running")
    trainer = subprocess.Popen(["sleep", "30"])  # stands for the training process
    try:
        info = json.loads((run / "run.json").read_text())
        info |= {"pid": trainer.pid, "host": os.uname().nodename}
        (run / "run.json").write_text(json.dumps(info))
        with pytest.raises(RunError, match=f"still training \\(pid {trainer.pid} on "):
            export_run(run, tmp_path / "O")
    finally:
        trainer.kill()
        trainer.wait()


def test_a_truncated_run_is_shipped(tmp_path):
    target = export_run(fake_run(tmp_path / "run", "truncated"), tmp_path / "O")
    assert target == tmp_path / "O" / "checkpoints" / "best-step000007.ckpt" and target.is_file()
    assert json.loads((tmp_path / "O" / "run.json").read_text())["status"] == "finished"


def test_a_failed_write_leaves_the_earlier_package_whole(tmp_path, monkeypatch, capsys):
    out = tmp_path / "O"
    export_run(fake_run(tmp_path / "first"), out)
    before = files(out)
    second = fake_run(tmp_path / "second", weights=5000, step=9)

    def full_disk(obj, path):
        Path(path).write_bytes(b"PK\x03\x04 half")
        raise RuntimeError(
            "[enforce fail at inline_container.cc:626] . unexpected pos 4160 vs 4096"
        )

    monkeypatch.setattr(export.torch, "save", full_disk)
    assert main([str(second), str(out)]) == 2
    assert capsys.readouterr().err == (
        f"error: OUT_DIR {out}: the new package could not be written in its staging folder "
        "beside it (no space left on device); the earlier package there is as it was: free "
        "space there, or choose another OUT_DIR\n"
    )
    assert files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["O", "first", "second"]


def test_ship_onto_a_real_full_disk_leaves_the_earlier_package(tmp_path):
    with mounted_tmpfs(tmp_path / "small", "size=2m") as disk:
        out = disk / "O"
        export_run(fake_run(tmp_path / "first"), out)
        before = files(out)
        with open(disk / "fill", "wb") as f:  # the disk full but for 64 KiB
            try:
                f.write(b"\0" * (3 << 20))
            except OSError:
                pass
        os.truncate(disk / "fill", os.path.getsize(disk / "fill") - 65536)
        free = shutil.disk_usage(disk).free
        with pytest.raises(ShipError) as err:
            export_run(fake_run(tmp_path / "second", weights=200_000, step=9), out)
        assert shutil.disk_usage(disk).free == free  # no file of the failed writer held open
        assert str(err.value).startswith(f"OUT_DIR {out}: the new package could not be written")
        assert "\n" not in str(err.value) and "(no space left on device)" in str(err.value)
        assert files(out) == before
        assert sorted(p.name for p in disk.iterdir()) == ["O", "fill"]
