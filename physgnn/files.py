"""Files written atomically (a ``<name>.tmp`` beside the target, flushed to disk, then renamed
over it), so an interrupted run or a full disk never leaves a half file under the real name;
CSV tables with typed reads; output folders that physgnn may write into (:func:`claim_folder`).
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import socket
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path

from physgnn import __version__
from physgnn.errors import PhysgnnError

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
    if folder.exists() and not folder.is_dir():
        raise FileExistsError(f"{key} {folder} is a file: choose another {key}")
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


class InUseError(PhysgnnError, RuntimeError):
    """Another process writes where this one would (one line naming it and the way out)."""


def process_alive(pid) -> bool:
    """Whether process ``pid`` of this host is alive (and not this process)."""
    if not isinstance(pid, int) or pid <= 0 or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


# A lock's holder touches it (its mtime) every LOCK_HEARTBEAT_S while it runs, so a lock of
# another host (whose pid cannot be asked after) left untouched for LOCK_STALE_S is a lost
# node's (a killed or requeued cluster job) and is taken over; a fresher one is refused.
LOCK_HEARTBEAT_S = 30.0
LOCK_STALE_S = 600.0


@contextmanager
def exclusive(lock: str | Path, what: str, way_out: str) -> Iterator[Path]:
    """Hold the file ``lock`` while the block runs: it is created exclusively, names this
    process (pid, host, since when) and is touched every :data:`LOCK_HEARTBEAT_S` (a
    heartbeat). A live holder makes :class:`InUseError` (``what`` is in use ..., then
    ``way_out``); the lock of a dead process of this host, or of another host untouched for
    :data:`LOCK_STALE_S`, is taken over. The lock is removed at the end, whatever happened."""
    lock = Path(lock)
    lock.parent.mkdir(parents=True, exist_ok=True)
    mine = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "since": datetime.now().isoformat(timespec="seconds"),
    }
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            _refuse_or_clear(lock, what, way_out)
            continue
        with os.fdopen(fd, "w") as f:
            json.dump(mine, f)
        break
    else:
        raise InUseError(f"{what} is in use (lock {lock} keeps changing hands): {way_out}")
    stop = threading.Event()
    beating = threading.Thread(target=_heartbeat, args=(lock, stop), daemon=True)
    beating.start()
    try:
        yield lock
    finally:
        stop.set()
        beating.join()
        if _holder(lock).get("pid") == mine["pid"]:
            lock.unlink(missing_ok=True)


def _heartbeat(lock: Path, stop: threading.Event) -> None:
    """Touch ``lock`` every :data:`LOCK_HEARTBEAT_S` until ``stop``: the holder still runs."""
    while not stop.wait(LOCK_HEARTBEAT_S):
        try:
            os.utime(lock)
        except OSError:  # removed by hand, or its disk went away: nothing to keep fresh
            pass


def _holder(lock: Path) -> dict:
    try:
        return json.loads(lock.read_text())
    except (OSError, ValueError):
        return {}


def _age(seconds: float) -> str:
    """``seconds`` in words: ``40 s``, ``12 min``, ``3.0 h``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min" if seconds < 7200 else f"{seconds / 3600:.1f} h"


def _refuse_or_clear(lock: Path, what: str, way_out: str) -> None:
    """A lock held by a live process of this host, or of another host touched within
    :data:`LOCK_STALE_S`, is refused (naming the holder, the lock's age and how to remove
    it); a dead one's, a silent one of another host (a warning line), or an unreadable one
    (its writer died at once), is removed."""
    holder = _holder(lock)
    here = holder.get("host") == socket.gethostname()
    try:
        silent = time.time() - lock.stat().st_mtime
    except OSError:  # released meanwhile
        return
    pid, host = holder.get("pid"), holder.get("host")
    if holder and not here and silent > LOCK_STALE_S:
        print(
            f"warning: {what}: taking over the lock {lock} of pid {pid} on {host}, untouched for"
            f" {_age(silent)} (a running holder touches it every {LOCK_HEARTBEAT_S:g} s: its "
            "node is gone)",
            file=sys.stderr,
        )
    elif holder and (not here or process_alive(pid)):
        gone = (
            f"if pid {pid} is not a physgnn process (its pid reused), remove the lock file {lock}"
            if here
            else f"remove {lock} if that process is gone (a lock of another host untouched "
            f"for {_age(LOCK_STALE_S)} is taken over: its holder touches it every "
            f"{LOCK_HEARTBEAT_S:g} s)"
        )
        raise InUseError(
            f"{what} is in use: pid {pid} on {host} writes there since {holder.get('since')} "
            f"(lock {lock}, touched {_age(silent)} ago): {way_out}; {gone}"
        )
    lock.unlink(missing_ok=True)


@contextmanager
def staged_outputs(folder: str | Path, key: str, outputs: Iterable[str]) -> Iterator[Path]:
    """Write a command's ``outputs`` (names in ``folder``) whole or not at all, one writer at a
    time. Holds ``<folder>.lock`` (a second writer is refused in one line, :func:`exclusive`)
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
