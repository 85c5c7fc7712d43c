"""The learning-rate decay defined by the run's length (physgnn/training/schedule.py): the
default, the long run and the GPU run end at one factor; the default's rates equal a per-epoch
``ExponentialLR(gamma=0.97)``; a step budget decays per step; a resumed run keeps its
schedule, a run trained further reaches the final factor at its new end."""

from __future__ import annotations

import functools
from types import SimpleNamespace

import pytest
import torch
from hydra.utils import instantiate
from trainkit import compose_train

from physgnn.errors import ConfigError
from physgnn.training.checks import check_arguments
from physgnn.training.schedule import RunLengthDecay, lr_scheduler

LR = 1.0e-3


def trainer_of(cfg) -> SimpleNamespace:
    """What :func:`run_length` reads of a trainer: its budget as Lightning resolves it."""
    return SimpleNamespace(max_epochs=cfg.trainer.max_epochs, max_steps=-1)


def rates(factory, trainer, steps: int | None = None) -> tuple[dict, list[float]]:
    """The scheduler entry of ``factory`` and the rate before each of its steps, and after."""
    optimizer = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=LR)
    entry = lr_scheduler(factory, optimizer, trainer)
    out = [optimizer.param_groups[0]["lr"]]
    for _ in range(steps if steps is not None else entry["scheduler"].length):
        optimizer.step()
        entry["scheduler"].step()
        out.append(optimizer.param_groups[0]["lr"])
    return entry, out


@pytest.mark.parametrize(
    ("overrides", "epochs"),
    [([], 90), (["+experiment=long"], 900), (["trainer=gpu", "data=paper"], 500)],
    ids=["default", "long", "gpu-paper"],
)
def test_the_default_long_and_gpu_runs_end_at_one_factor(overrides, epochs):
    cfg = compose_train(overrides)
    assert cfg.trainer.max_epochs == epochs
    entry, lrs = rates(instantiate(cfg.lit.scheduler), trainer_of(cfg))
    assert entry["interval"] == "epoch" and len(lrs) == epochs + 1
    assert lrs[-1] / LR == pytest.approx(0.97**90, rel=1e-12)  # 0.0645: ÷15.5


def test_the_default_decays_by_exactly_0_97_per_epoch():
    cfg = compose_train([])
    entry, lrs = rates(instantiate(cfg.lit.scheduler), trainer_of(cfg))
    # the factor the recipe's literal 0.0644846109465322 was: 0.97^90, bit for bit
    assert entry["scheduler"].final_lr_factor == 0.0644846109465322 == 0.97**90
    optimizer = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=LR)
    before = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=0.97)
    expected = [LR]
    for _ in range(90):
        optimizer.step()
        before.step()
        expected.append(optimizer.param_groups[0]["lr"])
    assert lrs == expected  # bit for bit: the default's schedule is the one it had


def test_a_step_budget_decays_per_step():
    decay = functools.partial(RunLengthDecay, decay_per_epoch=0.01, epochs=1)
    entry, lrs = rates(decay, SimpleNamespace(max_epochs=-1, max_steps=300))
    assert entry["interval"] == "step" and len(lrs) == 301
    assert lrs[-1] / LR == pytest.approx(0.01, rel=1e-12)
    # both bounds: the one that ends the run first
    ends_first = SimpleNamespace(max_epochs=10, max_steps=300, estimated_stepping_batches=300)
    assert rates(decay, ends_first, 0)[0]["interval"] == "step"
    epochs_first = SimpleNamespace(max_epochs=10, max_steps=300, estimated_stepping_batches=100)
    assert rates(decay, epochs_first, 0)[0]["scheduler"].length == 10


def test_a_run_without_end_is_one_line():
    decay = functools.partial(RunLengthDecay, decay_per_epoch=0.01, epochs=1)
    with pytest.raises(ConfigError, match="set trainer.max_epochs or trainer.max_steps"):
        rates(decay, SimpleNamespace(max_epochs=-1, max_steps=-1))
    with pytest.raises(ConfigError, match=r"decay_per_epoch must be a number in \(0, 1000\)"):
        rates(functools.partial(RunLengthDecay, decay_per_epoch=0.0), trainer_of(compose_train([])))
    with pytest.raises(ConfigError, match=r"^lit.scheduler.epochs must be a whole number >= 1"):
        rates(functools.partial(RunLengthDecay, epochs=0), trainer_of(compose_train([])))


def fresh(trainer) -> tuple:
    optimizer = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=LR)
    return optimizer, lr_scheduler(RunLengthDecay, optimizer, trainer)["scheduler"]


def resumed(trainer, saved: tuple) -> tuple:
    """A new run's optimizer and scheduler, restored from ``saved`` as Lightning does."""
    optimizer, scheduler = fresh(trainer)
    optimizer.load_state_dict(saved[0])
    scheduler.load_state_dict(saved[1])
    return optimizer, scheduler


def advance(optimizer, scheduler, epochs: int) -> list[float]:
    out = []
    for _ in range(epochs):
        optimizer.step()
        scheduler.step()
        out.append(optimizer.param_groups[0]["lr"])
    return out


def test_a_resumed_run_keeps_its_schedule_a_longer_one_ends_at_the_final_factor():
    epochs = functools.partial(SimpleNamespace, max_steps=-1)
    straight = advance(*fresh(epochs(max_epochs=90)), 90)
    optimizer, scheduler = fresh(epochs(max_epochs=90))
    first = advance(optimizer, scheduler, 30)
    saved = optimizer.state_dict(), scheduler.state_dict()
    # interrupted at epoch 30 and resumed: the same rates, bit for bit
    assert first + advance(*resumed(epochs(max_epochs=90), saved), 60) == straight
    # trained further to 180 epochs: from the checkpoint's rate down to the final factor
    longer = advance(*resumed(epochs(max_epochs=180), saved), 150)
    assert first[-1] > longer[0] > straight[30] and longer[-1] / LR == pytest.approx(0.97**90)
    # resumed at step 300 (10 a epoch) with a step budget of 900: per step, down to the factor
    by_steps = SimpleNamespace(max_epochs=-1, max_steps=900, global_step=300)
    optimizer, scheduler = resumed(by_steps, saved)
    assert scheduler.interval == "step" and scheduler.last_epoch == 300
    steps = advance(optimizer, scheduler, 600)
    assert first[-1] > steps[0] and steps[-1] / LR == pytest.approx(0.97**90)
    assert "progress" not in scheduler.state_dict()  # a checkpoint holds no trainer


def test_a_gamma_given_to_the_run_length_decay_is_one_line():
    # the command line refuses it before (physgnn/cli/overrides.py); train(cfg) here
    cfg = compose_train(["+lit.scheduler.gamma=0.995"])
    refused = r"gamma is not an argument of RunLengthDecay \(known: decay_per_epoch, epochs\)$"
    with pytest.raises(ConfigError, match=refused):
        check_arguments(cfg)
