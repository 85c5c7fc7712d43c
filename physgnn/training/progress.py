"""What a training run keeps through interruptions: its counters, and a clean stop on a signal.

:class:`RunProgress` counts the state pairs and spheres trained on (summed over DDP processes
once per epoch and before every checkpoint, not per step) and the training seconds, and stores
them in every checkpoint, so a resumed run continues the counts of the whole run.
:class:`StopOnSignal` turns Ctrl-C (SIGINT), SIGTERM and the pre-emption signal of a submitit
job (SIGUSR2) into a stop after the current batch (with DDP, within SIGNAL_CHECK_EVERY
batches, so that steps need not ask every process): all DDP processes stop at the same step,
``last.ckpt`` is saved there (mid-epoch) and ``fit`` ends with :class:`StopTraining`. A second
Ctrl-C stops at once. A signal whose handler belongs to a job scheduler is left to it (submitit
ignores SIGTERM), and after the run is recorded :meth:`StopOnSignal.chain` hands the pre-emption
signal on to it (submitit requeues the job).
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
import weakref
from pathlib import Path

import lightning as L
import torch

from physgnn.errors import replaceable, signal_name

log = logging.getLogger(__name__)


# (step, epoch) of the last.ckpt that save_last wrote, per checkpoint callback: saved once
_saved_at: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def save_last(trainer: L.Trainer, always: bool = False) -> Path | None:
    """Save ``last.ckpt`` beside the checkpoint callback's files when training moved on since
    its last save (time limit mid-epoch, a signal), or ``always``; returns the file (None
    without checkpoints or in a ``fast_dev_run``)."""
    ckpt = trainer.checkpoint_callback
    if ckpt is None or not ckpt.dirpath or trainer.fast_dev_run:
        return None
    for callback in trainer.callbacks:  # every process calls this at the same step
        if isinstance(callback, RunProgress):
            callback.flush(trainer)
    last = Path(ckpt.dirpath) / "last.ckpt"
    saved = {getattr(ckpt, "_last_global_step_saved", -1), _saved_at.get(ckpt)}
    if always or (trainer.global_step, trainer.current_epoch) not in saved:
        trainer.save_checkpoint(last)
        ckpt.last_model_path = str(last)
        _saved_at[ckpt] = (trainer.global_step, trainer.current_epoch)
    return last if last.exists() else None


class RunProgress(L.Callback):
    """Pairs and spheres trained on, training seconds and fit sessions of the whole run; keeps
    ``last.ckpt`` at the end of every epoch."""

    def __init__(self):
        self.pairs_seen = 0
        self.nodes_seen = 0
        self._pending = [0, 0]  # this process's pairs and spheres since the last flush
        self._sessions_before = 0
        self._seconds_before = 0.0
        self._start: float | None = None

    @property
    def sessions(self) -> int:
        """Calls of ``fit`` over the whole run: 1 + the times it was resumed."""
        return self._sessions_before + (self._start is not None)

    def seconds(self) -> float:
        """Training seconds of the whole run (earlier sessions included)."""
        now = 0.0 if self._start is None else time.perf_counter() - self._start
        return self._seconds_before + now

    def on_fit_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._start = time.perf_counter()

    def on_train_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        # Lightning refreshes last.ckpt only with a new best; a killed run (no signal to
        # catch) would restart from that epoch. Runs before ModelCheckpoint's own hook.
        self.flush(trainer)
        save_last(trainer)

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        self._pending[0] += batch.num_graphs  # host ints: nothing read from the device
        self._pending[1] += batch.num_nodes

    def on_validation_start(self, trainer, pl_module) -> None:
        self.flush(trainer)  # a checkpoint may follow the validation

    def on_train_end(self, trainer, pl_module) -> None:
        self.flush(trainer)

    def flush(self, trainer: L.Trainer) -> None:
        """Add the counts since the last flush, summed over the DDP processes (one all-reduce:
        every process must call it at the same point, as the hooks above do; each has trained
        on the same number of batches since the last flush, so all or none have counts)."""
        if self._pending == [0, 0]:
            return
        if trainer.world_size > 1:
            counts = torch.tensor(self._pending, device=trainer.strategy.root_device)
            self._pending = trainer.strategy.reduce(counts, reduce_op="sum").tolist()
        self.pairs_seen += int(self._pending[0])
        self.nodes_seen += int(self._pending[1])
        self._pending = [0, 0]

    def state_dict(self) -> dict:
        return {
            "pairs_seen": self.pairs_seen,
            "nodes_seen": self.nodes_seen,
            "train_time_s": self.seconds(),
            "sessions": self.sessions,
        }

    def load_state_dict(self, state_dict: dict) -> None:
        self.pairs_seen = int(state_dict.get("pairs_seen", 0))
        self.nodes_seen = int(state_dict.get("nodes_seen", 0))
        self._seconds_before = float(state_dict.get("train_time_s", 0.0))
        self._sessions_before = int(state_dict.get("sessions", 0))


class StopTraining(Exception):
    """Raised out of ``fit`` after a signal, at a batch boundary, once ``last.ckpt`` is saved."""

    def __init__(self, signum: int, checkpoint: Path | None):
        super().__init__(f"stopped by {signal_name(signum)}")
        self.signum = signum
        self.checkpoint = checkpoint


def preemption_signal() -> int | None:
    """The signal a submitit job is pre-empted with (None outside submitit)."""
    if not os.environ.get("SUBMITIT_EXECUTOR"):
        return None
    return getattr(signal, "SIG" + os.environ.get("SUBMITIT_PREEMPT_SIGNAL", "USR2"), None)


# With DDP, the processes agree on a stop every this many batches (and at an epoch's end)
SIGNAL_CHECK_EVERY = 10


class StopOnSignal(L.Callback):
    """Stop training cleanly on a signal (module doc); :meth:`install` before ``fit``,
    :meth:`restore` after."""

    def __init__(self):
        self.signum: int | None = None
        self._previous: dict[int, object] = {}

    def install(self) -> None:
        """Take SIGINT and SIGTERM where their handler is Python's default (or physgnn's),
        and a submitit job's pre-emption signal."""
        if threading.current_thread() is not threading.main_thread():
            return
        preempt = preemption_signal()
        for signum in {signal.SIGINT, signal.SIGTERM, preempt} - {None}:
            handler = signal.getsignal(signum)
            if signum not in self._previous and (replaceable(handler) or signum == preempt):
                self._previous[signum] = handler
            if signum in self._previous:
                signal.signal(signum, self._request)

    def restore(self) -> None:
        """Give every signal back the handler it had before :meth:`install`."""
        if threading.current_thread() is threading.main_thread():
            for signum, handler in self._previous.items():
                signal.signal(signum, handler)

    def chain(self) -> None:
        """Hand the signal received on to the scheduler's handler it replaced, if any."""
        previous = self._previous.get(self.signum)
        if callable(previous) and not replaceable(previous):
            previous(self.signum, None)

    def _request(self, signum: int, frame) -> None:
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt  # a second Ctrl-C: at once
        self.signum = signum
        log.warning(
            "%s received: stopping after this batch and saving checkpoints/last.ckpt "
            "(Ctrl-C again to stop at once)",
            signal_name(signum),
        )

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self.install()  # again: Lightning set its own SIGTERM handler when fit started

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx) -> None:
        if trainer.world_size == 1:
            if self.signum is None:
                return
        elif (batch_idx + 1) % SIGNAL_CHECK_EVERY and not trainer.is_last_batch:
            return  # asking the other processes is an all-reduce and a read-back
        elif not trainer.strategy.reduce_boolean_decision(self.signum is not None, all=False):
            return
        self.signum = self.signum or signal.SIGTERM  # another process was signalled
        raise StopTraining(self.signum, save_last(trainer, always=True))
