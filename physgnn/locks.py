"""An exclusive lock naming its holder: a file created exclusively, holding the process's pid,
host and start, kept fresh by a heartbeat while the holder runs (:func:`exclusive`); a live
holder is refused in one line (:class:`InUseError`), a dead one's lock taken over.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path

from physgnn.errors import PhysgnnError


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
