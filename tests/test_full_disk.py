"""Full and read-only disks as they really surface: h5py and torch wrap ENOSPC and EROFS in a
RuntimeError (not the OSError that injected faults raise). Each is one line, exit 2; a real
small filesystem (tmpfs, mounted when the suite runs as root) checks simulate end to end."""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

import pytest
from conftest import mounted_tmpfs
from omegaconf import OmegaConf

from physgnn import CONF_DIR
from physgnn import simulate as simulate_command
from physgnn.cli import command

TORCH_FULL = (
    "[enforce fail at inline_container.cc:664] . PytorchStreamWriter failed writing "
    "file data/0: file write failed"
)
H5PY_FULL = (
    "Can't decrement id ref count (file write failed: time = now, filename = 'x.h5', "
    "errno = 28, error message = 'No space left on device')"
)


@pytest.mark.parametrize("message", [TORCH_FULL, H5PY_FULL], ids=["torch", "h5py"])
def test_a_disk_error_wrapped_in_a_runtime_error_is_one_line(capsys, message):
    def full(cfg):
        raise RuntimeError(message)

    with pytest.raises(SystemExit) as exit_info:
        command("train", full).__wrapped__(OmegaConf.create())
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        "error: writing failed (disk full or read-only): the outputs folder; free space, or "
        "choose a writable paths.outputs (or PHYSGNN_OUTPUTS)\n"
    )


@pytest.fixture
def full_tmpfs(tmp_path):
    """A real 2 MiB filesystem with 16 KiB left (root only: it mounts a tmpfs)."""
    with mounted_tmpfs(tmp_path / "small", "size=2m") as mount:
        with open(mount / "fill", "wb") as f:
            try:
                f.write(b"\0" * (3 << 20))
            except OSError:
                pass
        os.truncate(mount / "fill", os.path.getsize(mount / "fill") - 16384)
        yield mount


def test_simulate_onto_a_real_full_disk_is_one_line_and_leaves_nothing(full_tmpfs, capsys):
    out = full_tmpfs / "sim"
    scene = Path(CONF_DIR) / "scene" / "throw.yaml"
    with pytest.raises(SystemExit) as exit_info:
        simulate_command.main([f"scene_file={scene}", "frames=1000", "video=false", f"out={out}"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1
    assert err.startswith("error: No space left on device: ")
    # no lock, no staging, and no out: the folder it made held nothing but its marker
    assert sorted(p.name for p in full_tmpfs.iterdir()) == ["fill"]


@pytest.mark.parametrize(
    ("module", "args", "key"),
    [
        ("physgnn.train", ["data=tiny", "run_dir={disk}/run"], "run_dir={disk}/run"),
        (
            "physgnn.generate",
            ["data=tiny", "paths.outputs={disk}/out", "workers=1"],
            "paths.outputs={disk}/out",
        ),
    ],
    ids=["train", "generate"],
)
def test_train_and_generate_onto_a_real_full_disk_are_one_line(
    full_tmpfs, module, args, key, monkeypatch, capsys
):
    """In-process, as the console script runs each command (their own processes are tested in
    tests/test_faults.py)."""
    argv = [a.format(disk=full_tmpfs) for a in args]
    monkeypatch.setattr(sys, "argv", [module, *argv])
    with pytest.raises(SystemExit) as exit_info:
        importlib.import_module(module).main()
    assert exit_info.value.code == 2
    (line,) = [x for x in capsys.readouterr().err.splitlines() if x.startswith("error")]
    assert line.startswith(f"error: {key.format(disk=full_tmpfs)} cannot be written (no space ")
    assert sorted(p.name for p in full_tmpfs.iterdir()) == ["fill"]  # nothing made there
