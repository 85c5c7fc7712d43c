"""The one base of every error of the user's making (bad config, missing or corrupt data).

A :class:`PhysgnnError` carries a message of one line that names the problem; every command
(:mod:`physgnn.cli`) prints it as ``error: <message>`` and exits with :attr:`exit_code`.
Anything else is a bug and keeps its traceback.

A command stopped from outside (Ctrl-C, ``kill``) is an :class:`Interrupted`: exit code
128 + the signal number, as a shell reports it. :func:`sigterm_interrupts` makes SIGTERM
raise ``KeyboardInterrupt`` like Ctrl-C, so ``finally`` blocks clean up after both;
:func:`forked_worker` readies the workers of a forked pool.
"""

from __future__ import annotations

import errno
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


class PhysgnnError(Exception):
    """An error of the user's making, told in one line."""

    exit_code = 2


def one_line(err: BaseException) -> str:
    """The message of ``err`` on one line (its non-empty lines joined by ``"; "``)."""
    return "; ".join(line.strip() for line in str(err).splitlines() if line.strip())


# What torch and h5py say (in a RuntimeError) when a write hit a full or read-only disk
# (torch's stream writer on a full disk: "file write failed", or "unexpected pos").
DISK_WORDS = (
    "No space left on device",
    "Read-only file system",
    "file write failed",
    "unexpected pos",
    "Disk quota exceeded",
)


# A disk that is full or not writable is the user's to fix, not a bug.
DISK_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM)


def disk_problem(err: BaseException) -> bool:
    """``err`` is an OSError of a full, read-only or forbidden place to write, or torch's or
    h5py's RuntimeError wrapping one."""
    if isinstance(err, OSError):
        return err.errno in DISK_ERRNOS
    return isinstance(err, RuntimeError) and any(w in str(err) for w in DISK_WORDS)


class ConfigError(PhysgnnError, ValueError):
    """A config value that cannot be used (missing, of the wrong kind or out of range)."""


class Interrupted(PhysgnnError):
    """A command stopped by a signal (Ctrl-C: SIGINT, ``kill``: SIGTERM); exit 128 + signal."""

    def __init__(self, message: str, signum: int = signal.SIGINT):
        super().__init__(message)
        self.signum = int(signum)
        self.exit_code = 128 + self.signum


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt(signum)


def replaceable(handler) -> bool:
    """True for a signal handler physgnn may take over: Python's defaults or its own. A job
    scheduler's handler is left alone (submitit ignores SIGTERM and pre-empts with SIGUSR2)."""
    return handler in (signal.SIG_DFL, signal.default_int_handler, _raise_interrupt, None)


@contextmanager
def sigterm_interrupts() -> Iterator[None]:
    """Within: SIGTERM raises ``KeyboardInterrupt(SIGTERM)`` in the main thread, as Ctrl-C
    raises ``KeyboardInterrupt``; the handler before is restored after."""
    previous = signal.getsignal(signal.SIGTERM)
    if threading.current_thread() is not threading.main_thread() or not replaceable(previous):
        yield
        return
    signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def forked_worker() -> None:
    """The initializer of physgnn's forked pools: the worker leaves Ctrl-C to the main process
    (no traceback per worker), dies on the pool's SIGTERM, and runs torch on one thread. GNU
    OpenMP is not fork-safe: a child forked from a process whose torch already ran a parallel
    loop on several threads waits forever at the team's barrier in its own first parallel loop
    (``make eval``'s pybullet rows hung so); on one thread ATen runs its loops inline."""
    import torch  # not at import: this module is the base every part imports

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    torch.set_num_threads(1)


def interrupt_signal(err: KeyboardInterrupt) -> int:
    """The signal a ``KeyboardInterrupt`` stands for (SIGTERM when raised by
    :func:`sigterm_interrupts`, else SIGINT)."""
    return signal.SIGTERM if err.args and err.args[0] == signal.SIGTERM else signal.SIGINT
