"""Files written atomically (a ``<name>.tmp`` beside the target, flushed to disk, then renamed
over it), so an interrupted run or a full disk never leaves a half file under the real name;
CSV tables with typed reads; output folders that physgnn may write into (:func:`claim_folder`)
and a command's outputs written whole, one writer at a time (:func:`staged_outputs`).
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import subprocess
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from physgnn import __version__
from physgnn.locks import exclusive

# Written into every output folder physgnn makes (simulate's out, eval's report_dir): the
# proof that physgnn may write over the files it holds.
OUTPUT_MARKER = "physgnn-output.json"


@contextmanager
def atomic_path(path: str | Path, keep_suffix: bool = False) -> Iterator[Path]:
    """Yield ``<path>.tmp`` to write; on success it is flushed to disk and replaces ``path``
    (folders are made), on an error (a full disk included) it is removed and ``path`` is left
    as it was. ``keep_suffix``: ``<stem>.tmp<suffix>`` instead, for writers that choose the
    format by the suffix."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    name = f"{path.stem}.tmp{path.suffix}" if keep_suffix else path.name + ".tmp"
    tmp = path.with_name(name)
    try:
        yield tmp
        _sync(tmp)
        os.replace(tmp, path)
        _sync(path.parent)
    finally:
        tmp.unlink(missing_ok=True)


def _sync(path: Path) -> None:
    """Flush ``path`` (a file, or a folder's entries) to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def portable(path: str | Path) -> str:
    """``path`` as committed files show it: relative to the working folder when it lies below
    it (``outputs/study/...``, not a machine's absolute path), else unchanged."""
    path = Path(path)
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def code_commit() -> str | None:
    """The git commit of the physgnn code that runs, ``+`` appended when its checkout has
    uncommitted changes to tracked files: what a result needs besides its seed and thread count
    to be made again. None for an installed wheel (no checkout of physgnn's own) or without
    git."""
    package = Path(__file__).resolve().parent

    def git(*args: str) -> str:
        command = ["git", "-C", str(package), *args]
        return subprocess.run(command, capture_output=True, text=True, check=True).stdout.strip()

    try:
        if (Path(git("rev-parse", "--show-toplevel")) / "physgnn").resolve() != package:
            return None  # a checkout of another project that holds this package
        rev = git("rev-parse", "--short=12", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.CalledProcessError):
        return None
    return rev + ("+" if dirty else "")


def write_text(path: str | Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def _finite(x):
    """``x`` with every non-finite float replaced by None (JSON has no NaN or inf)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    return x


def write_json(path: str | Path, data) -> Path:
    """``data`` as indented JSON (non-finite floats as null), written atomically."""
    return write_text(path, json.dumps(_finite(data), indent=2) + "\n")


def write_rows(path: str | Path, rows: list[dict], columns: list[str]) -> Path:
    """Write ``rows`` (dicts keyed by ``columns``; None → empty cell) to ``path`` atomically."""
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        for row in rows:
            w.writerow({k: "" if row.get(k) is None else row[k] for k in columns})
    return Path(path)


def read_rows(path: str | Path, floats: Iterable[str], ints: Iterable[str]) -> list[dict]:
    """Rows of a CSV with the ``floats`` and ``ints`` columns parsed (empty cell → None)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for k in floats:
            row[k] = float(row[k]) if row.get(k) not in (None, "") else None
        for k in ints:
            row[k] = int(float(row[k])) if row.get(k) not in (None, "") else None
    return rows


def claim_folder(
    folder: str | Path, key: str, overwrite: bool | None = False, ours: bool = False
) -> Path:
    """Make ``folder`` (if needed) for physgnn to write into, once it may: an absent or empty
    folder, one marked with :data:`OUTPUT_MARKER` or ``ours`` (the command's default folder
    under ``paths.outputs``) gets the marker; any other folder is written into only with
    ``overwrite`` (and stays unmarked), else :class:`FileExistsError`, one line naming ``key``,
    the folder and the fix (``overwrite=true`` only where the command takes it: ``overwrite``
    None says it does not)."""
    folder = Path(folder)
    blocked = file_in_the_way(folder)
    if blocked == folder:
        raise FileExistsError(f"{key} {folder} is a file: choose another {key}")
    if blocked is not None:
        raise FileExistsError(f"{key} {folder} lies in {blocked}, a file: choose another {key}")
    mine = ours or not folder.exists() or (folder / OUTPUT_MARKER).is_file()
    if not mine and any(folder.iterdir()):
        if overwrite:
            return folder
        raise FileExistsError(
            f"{key} {folder} is a folder with files that physgnn did not write (no "
            f"{OUTPUT_MARKER}): choose another {key}"
            + (", or pass overwrite=true to write over them" if overwrite is not None else "")
        )
    write_json(folder / OUTPUT_MARKER, {"physgnn_version": __version__})
    return folder


@contextmanager
def claimed(
    folder: str | Path, key: str, overwrite: bool | None = False, ours: bool = False
) -> Iterator[Path]:
    """:func:`claim_folder` for the block. Where ``folder`` was absent or empty and the block
    fails (a refused value, a missing run, an interrupt) before anything but the marker lies
    in it, the folder goes again: a command that wrote nothing leaves no folder behind. A
    folder that held anything keeps it."""
    folder = Path(folder)
    fresh = not folder.is_dir() or not any(folder.iterdir())
    claim_folder(folder, key, overwrite, ours)
    try:
        yield folder
    except BaseException:
        if fresh and [p.name for p in folder.iterdir()] == [OUTPUT_MARKER]:
            (folder / OUTPUT_MARKER).unlink()
            folder.rmdir()
        raise


@contextmanager
def claimed_outputs(
    folder: str | Path,
    key: str,
    outputs: Iterable[str],
    overwrite: bool | None = False,
    ours: bool = False,
) -> Iterator[Path]:
    """:func:`claimed` and :func:`staged_outputs` of one ``folder``: yields the staging folder
    of a command that writes its ``outputs`` whole into a folder it may write into."""
    with claimed(folder, key, overwrite, ours), staged_outputs(folder, key, outputs) as staging:
        yield staging


def file_in_the_way(folder: str | Path) -> Path | None:
    """The file where ``folder`` should be, or where one of the folders it lies in should be
    (it cannot be made); None where nothing is in the way."""
    place = Path(folder)
    while not place.exists() and place != place.parent:
        place = place.parent
    return None if place.is_dir() or not place.exists() else place


@contextmanager
def staged_outputs(folder: str | Path, key: str, outputs: Iterable[str]) -> Iterator[Path]:
    """Write a command's ``outputs`` (names in ``folder``) whole or not at all, one writer at a
    time. Holds ``<folder>.lock`` (a second writer is refused in one line,
    :func:`~physgnn.locks.exclusive`)
    and yields this process's staging folder ``<folder>.partial-<pid>``; at the end the
    previous outputs leave ``folder`` and the staged ones move in. On an error or an interrupt
    the staging folder goes and ``folder`` keeps what it held. Other files in ``folder`` are
    never touched."""
    folder = Path(folder)
    lock = folder.with_name(folder.name + ".lock")
    way_out = f"wait for it to end, or choose another {key}"
    with exclusive(lock, f"{key} {folder}", way_out):
        staging = _fresh_staging(folder)
        try:
            yield staging
            _publish(staging, folder, tuple(outputs))
        finally:
            shutil.rmtree(staging, ignore_errors=True)


def _fresh_staging(folder: Path) -> Path:
    """This process's empty staging folder beside ``folder``, once the leftovers of interrupted
    writers (marked, under the lock held) are gone; an unmarked one in the way is refused."""
    for old in folder.parent.glob(f"{folder.name}.partial-*"):
        if (old / OUTPUT_MARKER).is_file():
            shutil.rmtree(old, ignore_errors=True)
    staging = folder.with_name(f"{folder.name}.partial-{os.getpid()}")
    if staging.exists():
        raise FileExistsError(f"{staging} is in the way and physgnn did not write it: move it")
    staging.mkdir(parents=True)
    write_json(staging / OUTPUT_MARKER, {"physgnn_version": __version__})
    return staging


def _publish(staging: Path, folder: Path, outputs: tuple[str, ...]) -> None:
    """The previous outputs out of ``folder``, the staged ones in. In a folder of the user's
    (no :data:`OUTPUT_MARKER`: written with ``overwrite=true``) an output folder is merged
    instead: only the files physgnn writes now are replaced, the user's others stay."""
    folder.mkdir(parents=True, exist_ok=True)
    ours = (folder / OUTPUT_MARKER).is_file()
    for name in outputs:
        old = folder / name
        if old.is_dir() and not ours:
            continue
        shutil.rmtree(old) if old.is_dir() else old.unlink(missing_ok=True)
    for item in staging.iterdir():
        if item.name == OUTPUT_MARKER:
            continue
        target = folder / item.name
        _merge(item, target) if target.is_dir() and item.is_dir() else os.replace(item, target)


def _merge(source: Path, target: Path) -> None:
    """Each file under ``source`` moved to its place under ``target``; other files stay."""
    for path in sorted(source.rglob("*")):
        if path.is_file():
            place = target / path.relative_to(source)
            place.parent.mkdir(parents=True, exist_ok=True)
            os.replace(path, place)
