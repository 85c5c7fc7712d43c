"""The learning-rate decay, defined by the length of the run.

:class:`RunLengthDecay` multiplies the rate by the same factor ``gamma`` each epoch, with
``gamma = final_lr_factor ** (1 / epochs of the run)``, so that every run ends at
``final_lr_factor`` × its initial rate, whatever its length: the default's 90 CPU epochs,
``+experiment=long``'s 900 and ``trainer=gpu``'s 500 alike. The recipe gives the factor as the
decay of a run of its own length, ``final_lr_factor = decay_per_epoch ** epochs`` (default
``0.97 ** 90``): on the default run, ``gamma`` is exactly 0.97, the rate of a per-epoch
``ExponentialLR(gamma=0.97)``.

The run's length is the trainer's (:func:`run_length`): ``trainer.max_epochs`` epochs, or, where
``trainer.max_steps`` ends the run first, that many optimiser steps with the decay stepped per
step. A resumed run restores ``gamma`` from its checkpoint and so continues the same schedule;
a run trained further or shorter (``ckpt_path=`` with another ``trainer.max_epochs`` or
``trainer.max_steps``) goes on from the checkpoint's rate and reaches ``final_lr_factor`` at
its own end.
"""

from __future__ import annotations

import functools

from omegaconf import DictConfig, OmegaConf
from torch.optim.lr_scheduler import ExponentialLR

from physgnn.errors import ConfigError
from physgnn.ranges import number, whole

# The default's decay: 0.97 per epoch over its 90 epochs (÷15.5 over the run)
DECAY_PER_EPOCH, EPOCHS = 0.97, 90
# A factor per epoch: at 0 the rate vanishes, below it turns negative (gradient ascent, and the
# run still "finishes")
DECAY = number(
    0, 1e3, above=True, below=True, what="lr x decay_per_epoch^epochs at the end; 1 keeps the rate"
)
EPOCHS_RANGE = whole(
    1, what="the run length at which the rate falls by decay_per_epoch each epoch", exact=True
)
GAMMA = number(0, 1e3, above=True, below=True, what="lr x gamma^epoch; 1 keeps the rate", example=1)


class RunLengthDecay(ExponentialLR):
    """Exponential decay to ``final_lr_factor = decay_per_epoch ** epochs`` × the initial rate
    over ``length`` epochs (or steps, ``interval="step"``); ``length``, ``interval`` and
    ``progress`` (the epochs or steps done, read when a checkpoint is restored) come from the
    trainer (:func:`lr_scheduler`), ``decay_per_epoch`` and ``epochs`` from the config."""

    def __init__(
        self,
        optimizer,
        decay_per_epoch: float = DECAY_PER_EPOCH,
        epochs: int = EPOCHS,
        length: int = 1,
        interval: str = "epoch",
        progress=None,
        last_epoch: int = -1,
    ):
        check_decay(decay_per_epoch, epochs)
        final_lr_factor = decay_per_epoch**epochs
        self.final_lr_factor, self.length, self.interval = final_lr_factor, length, interval
        self.progress = progress
        super().__init__(optimizer, gamma=final_lr_factor ** (1 / length), last_epoch=last_epoch)

    def state_dict(self) -> dict:
        return {k: v for k, v in super().state_dict().items() if k != "progress"}

    def load_state_dict(self, state_dict: dict) -> None:
        """The checkpoint's schedule; where this run is longer or shorter than the
        checkpoint's (or bounded by steps where it was by epochs, or the other way round), a
        new ``gamma`` that takes the checkpoint's rate to ``final_lr_factor`` at this run's
        end."""
        mine = self.length, self.interval, self.progress
        super().load_state_dict(state_dict)
        self.progress = mine[2]
        if mine[:2] == (self.length, self.interval):
            return
        done = self.last_epoch if mine[1] == self.interval or not mine[2] else mine[2]()
        factor = self._last_lr[0] / self.base_lrs[0]
        self.length, self.interval, self.last_epoch = mine[0], mine[1], max(done, 0)
        self.gamma = (self.final_lr_factor / factor) ** (1 / max(self.length - done, 1))


def run_length(trainer) -> tuple[str, int]:
    """``("epoch", max_epochs)``, or ``("step", max_steps)`` where the step budget ends the run
    first; a one-line ConfigError for a run without an end."""
    epochs, steps = trainer.max_epochs, trainer.max_steps
    has_epochs = epochs is not None and epochs >= 1
    has_steps = steps is not None and steps >= 1
    if has_epochs and has_steps:  # whichever ends the run first
        has_steps = int(trainer.estimated_stepping_batches) >= steps
    if has_steps:
        return "step", int(steps)
    if has_epochs:
        return "epoch", int(epochs)
    raise ConfigError(
        "lit.scheduler (RunLengthDecay) decays over the run's length and this run has none: set "
        "trainer.max_epochs or trainer.max_steps, or lit.scheduler=null for a constant rate"
    )


def _takes_run_length(factory) -> bool:
    func = factory.func if isinstance(factory, functools.partial) else factory
    return isinstance(func, type) and issubclass(func, RunLengthDecay)


def lr_scheduler(factory, optimizer, trainer) -> dict:
    """Lightning's ``lr_scheduler`` entry of ``factory(optimizer)``: a :class:`RunLengthDecay`
    given the trainer's :func:`run_length`, any other scheduler stepped once per epoch."""
    if not _takes_run_length(factory):
        return {"scheduler": factory(optimizer), "interval": "epoch"}
    if trainer is None:
        raise ConfigError("RunLengthDecay needs the trainer's run length: call it under fit")
    interval, length = run_length(trainer)

    def progress() -> int:  # read when a checkpoint is restored, after the trainer's loops
        return trainer.global_step if interval == "step" else trainer.current_epoch

    scheduler = factory(optimizer, length=length, interval=interval, progress=progress)
    return {"scheduler": scheduler, "interval": interval}


def check_decay(decay_per_epoch, epochs) -> None:
    """``decay_per_epoch`` a number > 0 (at 0 the rate vanishes, below it turns negative:
    gradient ascent, and the run still "finishes") and ``epochs`` a whole number >= 1."""
    key = "lit.scheduler"
    DECAY.check(
        f"{key}.decay_per_epoch",
        decay_per_epoch,
        f"the default: {key}.decay_per_epoch={DECAY_PER_EPOCH}",
    )
    EPOCHS_RANGE.check(f"{key}.epochs", epochs, f"the default: {key}.epochs={EPOCHS}")


def check_scheduler(lit_cfg: DictConfig | None) -> None:
    """A :class:`RunLengthDecay`'s ``decay_per_epoch`` and ``epochs`` (:func:`check_decay`), or
    an ``ExponentialLR``'s ``gamma`` (its factor per epoch) a number > 0, before anything is
    built."""
    node = OmegaConf.select(lit_cfg, "scheduler") if lit_cfg is not None else None
    if node is None:
        return
    if "decay_per_epoch" in node or "epochs" in node:
        check_decay(node.get("decay_per_epoch", DECAY_PER_EPOCH), node.get("epochs", EPOCHS))
    if node.get("gamma") is not None:
        GAMMA.check("lit.scheduler.gamma", node.get("gamma"))
