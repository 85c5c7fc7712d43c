"""The folders a command writes in, checked before Hydra makes its output folder there (else
Hydra's own traceback): not a file nor in one, and writable (a read-only or forbidden
``paths.outputs`` is one line naming it and the fix)."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from physgnn.errors import ConfigError
from physgnn.files import file_in_the_way
from physgnn.overrides import given as given_overrides

# Folders Hydra makes (or a command writes under) before any command runs; a mistake in one
# would be Hydra's traceback.
OUTPUT_KEYS = ("hydra.run.dir", "hydra.sweep.dir", "run_dir")
# The key of each command's own folder (its hydra.run.dir; under paths.outputs unless given),
# where it is not paths.outputs itself; None: a command for which Hydra makes no folder
# (data_report writes nothing; simulate writes its out itself, its disk errors one line).
OWN_FOLDER = {
    "eval": "report_dir",
    "bench": "out_dir",
    "sleep_study": "out",
    "study": "runs_dir",
    "data_report": None,
    "simulate": None,
}


MIN_FREE = 1 << 20  # bytes: less than this free and Hydra's own first writes may fail


def check_outputs_env(argv: list[str] | None = None, own: str | None = "paths.outputs") -> None:
    """``PHYSGNN_OUTPUTS``, where set, and ``paths.outputs=`` on the command line are not
    files; the folders the command writes in are no file nor in one (:func:`check_not_a_file`)
    and may be written (:func:`unwritable`): those of :data:`OUTPUT_KEYS` and ``own`` (the
    command's own folder, :data:`OWN_FOLDER`) given, else ``paths.outputs`` (or
    ``PHYSGNN_OUTPUTS``), which may be read-only where one is given.
    Hydra makes its output folder there before any command runs, and would fail with a
    traceback."""
    outputs = os.environ.get("PHYSGNN_OUTPUTS")
    if outputs and os.path.exists(outputs) and not os.path.isdir(outputs):
        raise ConfigError(
            f"PHYSGNN_OUTPUTS={outputs} is a file: set it to a folder (physgnn writes its data, "
            "runs and reports there), or unset it to write into ./outputs"
        )
    given = {
        key: str(o.value) if o.value is not None else ""
        for key, o in given_overrides(sys.argv[1:] if argv is None else argv).items()
    }
    value = given.get("paths.outputs")
    if value and os.path.exists(value) and not os.path.isdir(value):
        raise ConfigError(
            f"paths.outputs={value} is a file: give a folder (physgnn writes its data, "
            "runs and reports there), or leave it out to write into ./outputs"
        )
    keys = [k for k in (*OUTPUT_KEYS, own) if k and k != "paths.outputs" and given.get(k)]
    named = {key: (key, given[key]) for key in keys}
    if own is not None and not named:  # the command's folder lies under paths.outputs
        named["paths.outputs"] = (
            ("paths.outputs", value)
            if value
            else (("PHYSGNN_OUTPUTS", outputs) if outputs else ("paths.outputs", "outputs"))
        )
    for key, (name, folder) in named.items():
        check_not_a_file(name, folder)
        why = unwritable(folder)
        if why:
            raise ConfigError(
                f"{name}={folder} cannot be written ({why}): choose a writable "
                + ("paths.outputs (or PHYSGNN_OUTPUTS)" if key == "paths.outputs" else key)
            )


def check_not_a_file(key: str, folder: str) -> None:
    """``folder``, the value of ``key``, is no file and lies in no file (else Hydra's mkdir
    fails with its traceback)."""
    blocked = file_in_the_way(folder)
    if blocked is None:
        return
    where = "is a file" if blocked == Path(folder) else f"lies in {blocked}, a file"
    raise ConfigError(f"{key}={folder} {where}: choose a folder for {key}")


def unwritable(folder: str) -> str | None:
    """Why ``folder`` (or, where it is not yet there, the folder it would be made in) cannot
    be written: ``"read-only file system: /x"``, ``"no permission to write in /x"``,
    ``"no space left on device: N KiB free in /x"`` (below :data:`MIN_FREE`); None where it
    can."""
    place = os.path.abspath(folder)
    while not os.path.exists(place):
        place = os.path.dirname(place)
    if not os.path.isdir(place):
        return None  # a file in the way: check_not_a_file names it
    if os.access(place, os.W_OK | os.X_OK):
        free = shutil.disk_usage(place).free
        # Hydra writes its config files (tens of kB) before any command can catch an error
        return (
            f"no space left on device: {free >> 10} KiB free in {place}"
            if free < MIN_FREE
            else None
        )
    if hasattr(os, "statvfs") and os.statvfs(place).f_flag & os.ST_RDONLY:
        return f"read-only file system: {place}"
    return f"no permission to write in {place}"
