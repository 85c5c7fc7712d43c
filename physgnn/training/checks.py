"""Checks of a training config's values before anything is built or trained, each failing in
one line that names the key: values against the types and ranges of the constructor arguments
they feed, the learning rate, the step budget, the callbacks' monitors and that ``ckpt_path``
names a checkpoint. The run folder and whether the checkpoint a training starts from reads
whole and fits the model are checked by :mod:`physgnn.training.resume_checks`."""

from __future__ import annotations

import dataclasses
import inspect
import types
import typing
from pathlib import Path

from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError
from physgnn.ranges import number, whole
from physgnn.training.ranges import check_range

HYDRA_KEYS = {"_target_", "_partial_", "_recursive_", "_convert_", "_args_"}
# What the rollout callback logs (physgnn/training/callbacks.py)
ROLLOUT_METRICS = (
    "val/rollout_score",
    "val/mse20",
    "val/rollout_mse",
    "val/chamfer",
    "val/energy_gain",
    "val/max_depth",
    "val/tunnelled",
    "val/rest_drift",
)
# Constructor arguments that the code passes, not the config
PASSED = (
    "self",
    "stats",
    "simulator",
    "optimizer",
    "length",
    "interval",
    "progress",
    "last_epoch",
)
# The first bytes of a file torch.save writes: a zip, or a pickle (before torch 1.6)
CHECKPOINT_MAGIC = (b"PK", b"\x80")
LEARNING_RATE = number(0, above=True)
BUDGET = whole(1, also=(-1, None), what="-1 or null: no limit", example=10, exact=True)
WORDS = {int: "a whole number", float: "a number", bool: "true or false", str: "a string"}


def _fits(value, hint) -> bool:
    """Whether ``value`` has the annotated type (only ``int``, ``float``, ``bool``, ``str``,
    None and their unions are checked; anything else fits)."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return any(_fits(value, h) for h in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if hint in (bool, str):
        return isinstance(value, hint)
    return True


def _words(hint) -> str:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " or ".join(_words(h) for h in typing.get_args(hint))
    return "null" if hint is type(None) else WORDS.get(hint, str(hint))


def check_arguments(
    cfg: DictConfig, sections=("model", "datamodule", "lit", "lit.scheduler")
) -> None:
    """Every key of each ``_target_`` section (and of the ``_target_`` nodes within it:
    ``model.network``) is an argument of its constructor, of the annotated type
    (``model.network.M=abc``: ``model.network.M must be a whole number, got 'abc'``); a node
    whose target is a dataclass (``lit.noise``) is made here, so that its own range checks
    speak before Hydra would wrap them."""
    for section in sections:
        node = OmegaConf.select(cfg, section)
        if isinstance(node, DictConfig) and "_target_" in node:
            _check_node(node, section)


def _check_node(node: DictConfig, section: str) -> None:
    target = get_class(node._target_)
    params = inspect.signature(target).parameters
    try:
        hints = typing.get_type_hints(target.__init__)
    except (NameError, TypeError):
        hints = {}
    for key in node:
        if key in HYDRA_KEYS:
            continue
        if key not in params:
            known = ", ".join(k for k in params if k not in PASSED)
            raise ConfigError(
                f"{section}.{key} is not an argument of {target.__name__} (known: {known})"
            )
        value = OmegaConf.select(node, key)
        if isinstance(value, DictConfig):
            if "_target_" in value:
                _check_node(value, f"{section}.{key}")
            continue
        if not _fits(value, hints.get(key)):
            raise ConfigError(f"{section}.{key} must be {_words(hints[key])}, got {value!r}")
        check_range(f"{section}.{key}", value)
    if dataclasses.is_dataclass(target):
        target(**{k: OmegaConf.select(node, k) for k in node if k not in HYDRA_KEYS})


def check_optimizer(lit_cfg: DictConfig | None) -> None:
    """``lit.optimizer.lr`` is a positive number (torch's optimizers fail deep inside
    ``fit`` otherwise)."""
    lr = OmegaConf.select(lit_cfg, "optimizer.lr") if lit_cfg is not None else None
    if lr is not None:
        fix = "conf/lit/default.yaml: lit.optimizer.lr, default 1.0e-3"
        LEARNING_RATE.check("lit.optimizer.lr", lr, fix)


def check_budget(trainer_cfg: DictConfig) -> None:
    """``trainer.max_epochs`` and ``trainer.max_steps`` are whole numbers (Lightning asserts
    so deep inside ``fit``) that train something: >= 1, or -1 (no limit) or null."""
    for key in ("max_epochs", "max_steps"):
        BUDGET.check(f"trainer.{key}", trainer_cfg.get(key))


def check_monitors(callbacks_cfg: DictConfig | None) -> None:
    """A callback that watches a ``val/rollout…`` or other rollout metric needs the rollout
    callback, the only one that logs them (else Lightning fails at the first validation)."""
    callbacks = dict(callbacks_cfg or {})
    rollout = any(
        str(c.get("_target_", "")).endswith("RolloutCallback") for c in callbacks.values() if c
    )
    for name, c in callbacks.items():
        watched = str((c or {}).get("monitor") or "")
        ours = watched in ROLLOUT_METRICS or watched.startswith(("ood/", "val/mse"))
        if ours and not rollout:
            raise ConfigError(
                f"callbacks.{name}.monitor={watched} is logged by the rollout callback only: "
                f"keep callbacks.rollout, or set callbacks.{name}.monitor=val/loss"
            )


def not_a_checkpoint(path: Path) -> bool:
    """Whether the file ``path`` holds something else than ``torch.save`` writes (text, an
    image ...); an empty file or one cut short is a checkpoint, truncated."""
    try:
        with open(path, "rb") as f:
            start = f.read(2)
    except OSError:
        return False  # torch.load says what
    return bool(start) and not start.startswith(CHECKPOINT_MAGIC)


def check_ckpt_path(ckpt_path) -> None:
    """``ckpt_path``, when given, is a file that ``torch.save`` wrote (a zip; a text file or a
    run folder is not one), else one line with the fix."""
    if not ckpt_path:
        return
    fix = "give a run's .ckpt (<run>/checkpoints/last.ckpt)"
    if not Path(str(ckpt_path)).is_file():
        raise ConfigError(
            f"ckpt_path={ckpt_path}: no such file (a run keeps its checkpoints in "
            "<run_dir>/checkpoints/, last.ckpt the latest)"
        )
    if not_a_checkpoint(Path(str(ckpt_path))):
        raise ConfigError(
            f"ckpt_path={ckpt_path} is not a checkpoint (torch.save writes a zip, this file is "
            f"not one): {fix}"
        )
