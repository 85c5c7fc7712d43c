"""The Lightning trainer of a training config, and the data module and Lightning module it
trains, every value checked before anything is built.

Several processes (``trainer.devices`` other than 1, or ``trainer.num_nodes`` > 1) train with
DDP that looks for parameters without gradient at every step, whatever the accelerator: the
network skips the MLPs of interactions a batch lacks (no contacts: no pp MLP), and plain DDP
fails at the first such step. The config's ``strategy: auto`` (Lightning's default) is turned
into that strategy; a DDP strategy that does not look for them is refused in one line.
"""

from __future__ import annotations

import logging
import re
import typing
from datetime import timedelta

import lightning as L
import torch
from hydra.utils import instantiate
from lightning.fabric.plugins.precision.precision import _PRECISION_INPUT
from lightning.pytorch.strategies import DDPStrategy
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import InterpolationResolutionError

from physgnn.errors import ConfigError
from physgnn.ranges import check_seed, whole
from physgnn.training.checkpoint_io import AtomicCheckpointIO
from physgnn.training.checks import (
    check_arguments,
    check_budget,
    check_ckpt_path,
    check_monitors,
    check_optimizer,
)
from physgnn.training.ranges import check_range
from physgnn.training.schedule import check_scheduler
from physgnn.training.tracking import log_config

NUMERIC_TRAINER_KEYS = ("max_epochs", "max_steps", "gradient_clip_val", "log_every_n_steps")
FINDS_UNUSED = "_find_unused_parameters_true"
# What Lightning's Trainer takes for precision (it fails deep inside, wrapped by Hydra, else)
PRECISIONS = [v for part in typing.get_args(_PRECISION_INPUT) for v in typing.get_args(part)]
# What Lightning's Timer takes for max_time: a string DD:HH:MM:SS, or a mapping of timedelta's
DURATION = re.compile(r"(\d+):(\d\d):(\d\d):(\d\d)")
DEVICE_LIST = re.compile(r"\d+(,\d+)*,?")  # "0,1", "0,": device indices


log = logging.getLogger(__name__)


def check_trainer_config(trainer_cfg: DictConfig) -> None:
    """Catch a value Lightning would fail on deep inside ``fit`` (or that Hydra's "Error in
    call to target" would wrap), or would take silently: a non-numeric number, the devices, the
    clock guard, the gradient clipping, the accelerator, the precision and the strategy."""
    for key in NUMERIC_TRAINER_KEYS:
        value = trainer_cfg.get(key)
        if value is not None and not isinstance(value, int | float):
            raise ConfigError(f"trainer.{key} must be a number, got {value!r}")
    check_range("trainer.gradient_clip_val", trainer_cfg.get("gradient_clip_val"))
    check_devices(trainer_cfg.get("devices"), trainer_cfg.get("accelerator"))
    check_max_time(trainer_cfg.get("max_time"))
    if trainer_cfg.get("accelerator") in ("gpu", "cuda") and not torch.cuda.is_available():
        raise ConfigError(
            f"trainer.accelerator={trainer_cfg.accelerator} needs a CUDA GPU and torch sees "
            "none (torch.cuda.is_available() is False): train on the CPU (trainer=cpu, the "
            "default), or on a machine with a GPU and a CUDA build of torch"
        )
    precision = trainer_cfg.get("precision")
    if precision is not None and precision not in PRECISIONS:
        words = ", ".join(p for p in PRECISIONS if isinstance(p, str) and "-" in p)
        raise ConfigError(f"trainer.precision must be one of {words}, got {precision!r}")
    strategy = trainer_cfg.get("strategy")
    if isinstance(strategy, str) and strategy.startswith("ddp"):
        if not strategy.endswith(FINDS_UNUSED):
            fix = strategy.removesuffix("_find_unused_parameters_false") + FINDS_UNUSED
            raise ConfigError(
                f"trainer.strategy={strategy} fails at the first batch without contacts (the "
                f"network skips the MLPs a batch lacks): leave trainer.strategy=auto (DDP is "
                f"chosen for several devices) or set trainer.strategy={fix}"
            )


def check_devices(devices, accelerator=None) -> None:
    """``trainer.devices`` is what Lightning takes: a whole number >= 1 or ``auto``; besides,
    on an accelerator other than the CPU, -1 (all GPUs), a list of device indices or a string
    of them (``"0,1"``)."""
    cpu = accelerator == "cpu"
    if devices is None or devices == "auto" or _names_devices(devices, cpu):
        return
    more = "" if cpu else ", -1 (all GPUs), or a list of device indices ([0, 1] or '0,1')"
    where = " on the CPU (trainer.accelerator=cpu)" if cpu else ""
    raise ConfigError(
        f"trainer.devices must be a whole number >= 1, auto{more}{where}, got "
        f"{_written(devices)!r} (e.g. trainer.devices=1)"
    )


def _names_devices(devices, cpu: bool) -> bool:
    """Whether ``devices`` (not ``auto``) names at least one device (``cpu``: a count only)."""
    if OmegaConf.is_list(devices) or isinstance(devices, list | tuple):
        return not cpu and len(devices) > 0 and all(_whole(d) and d >= 0 for d in devices)
    if isinstance(devices, str):
        text = devices.replace(" ", "")
        if not cpu and "," in text and DEVICE_LIST.fullmatch(text):
            return True
        devices = int(text) if re.fullmatch(r"-?\d+", text) else None
    return _whole(devices) and (devices >= 1 or devices == -1 and not cpu)


def _whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _written(value):
    """``value`` as plain Python (a list, not a ListConfig), for a message."""
    return OmegaConf.to_container(value) if OmegaConf.is_config(value) else value


def check_max_time(max_time) -> None:
    """``trainer.max_time`` (the clock guard) is null or a duration Lightning's Timer takes, of
    more than 0 s: ``DD:HH:MM:SS``, or a mapping of ``days``, ``hours``, ``minutes``,
    ``seconds`` ... (Python's ``timedelta``)."""
    if max_time is None:
        return
    value = _written(max_time)
    seconds = _seconds(value)
    if seconds is None or seconds <= 0:
        raise ConfigError(
            "trainer.max_time must be a duration > 0 written DD:HH:MM:SS (days, hours, minutes, "
            "seconds) or a mapping of days, hours, minutes, seconds, or null (no clock guard), "
            f"got {value!r} (e.g. trainer.max_time=00:04:00:00: 4 hours)"
        )


def _seconds(value) -> float | None:
    """The seconds of a duration of :func:`check_max_time`, None when it is none."""
    if isinstance(value, str):
        found = DURATION.fullmatch(value.strip())
        if not found:
            return None
        days, hours, minutes, seconds = map(int, found.groups())
        return timedelta(days=days, hours=hours, minutes=minutes, seconds=seconds).total_seconds()
    if isinstance(value, dict):
        try:
            return timedelta(**value).total_seconds()
        except TypeError:  # a key timedelta does not take, a value not a number
            return None
    return None


def several_processes(trainer_cfg: DictConfig) -> bool:
    """Whether the trainer may start several processes: ``devices`` other than 1 (2, -1,
    ``auto``, ``"0,1"``, a list of several), or ``num_nodes`` > 1."""
    devices, nodes = trainer_cfg.get("devices", "auto"), trainer_cfg.get("num_nodes")
    if isinstance(nodes, int) and nodes > 1:
        return True
    if OmegaConf.is_list(devices) or isinstance(devices, list | tuple):
        return len(devices) > 1
    return str(devices).strip().rstrip(",") not in ("1", "0")  # "0,": the GPU of index 0


def strategy_of(trainer_cfg: DictConfig):
    """The trainer's strategy: the config's, but for ``auto`` (or none) on several processes
    a :class:`DDPStrategy` that finds unused parameters (module doc)."""
    strategy = trainer_cfg.get("strategy") or "auto"
    if strategy == "auto" and several_processes(trainer_cfg):
        return DDPStrategy(find_unused_parameters=True)
    return strategy


def check_val_rollout(cfg: DictConfig) -> None:
    """The validation rollouts' size, named by the key that sets it (``data.val_rollout`` of
    the preset, or ``callbacks.rollout``): whole numbers, at least one trajectory, the score's
    horizon at least 1 frame, and frames (of the OOD rollouts) null (whole trajectories) or
    enough for one predicted frame (``model.H`` + 2)."""
    node = OmegaConf.select(cfg, "callbacks.rollout")
    if node is None:
        return
    least = {"n_val_trajectories": 1, "max_frames": int(cfg.model.H) + 2, "horizon": 1}
    keys = (("n_val_trajectories", "trajectories"), ("max_frames", "frames"), ("horizon",) * 2)
    for key, origin in keys:
        if key not in node:  # a callbacks config of its own without it: the default
            continue
        from_data = OmegaConf.is_interpolation(node, key)
        name = f"data.val_rollout.{origin}" if from_data else f"callbacks.rollout.{key}"
        try:
            value = node[key]
        except InterpolationResolutionError:
            raise ConfigError(
                f"{name} is missing (data={cfg.data.name}): add val_rollout: {{trajectories: "
                "10, frames: null, horizon: 20} to the preset, as conf/data/small.yaml has it"
            ) from None
        if key == "max_frames" and value is None:
            continue
        whole(least[key], exact=True).check(name, value)


def check_rollout_values(cfg: DictConfig) -> None:
    """The rollout callback's other values (``every_n_epochs``, the score's weights) in their
    :data:`~physgnn.training.ranges.RANGES`."""
    node = OmegaConf.select(cfg, "callbacks.rollout")
    for key in ("every_n_epochs", "w_depth", "w_tunnel", "w_rest"):
        if node is not None and key in node:
            check_range(f"callbacks.rollout.{key}", node[key])


def check_trainer(cfg: DictConfig) -> None:
    """The trainer's values and the callbacks' monitors and sizes (before Lightning fails on
    them)."""
    check_trainer_config(cfg.trainer)
    check_budget(cfg.trainer)
    check_monitors(cfg.get("callbacks"))
    check_val_rollout(cfg)
    check_rollout_values(cfg)


def check_config(cfg: DictConfig) -> None:
    """Every value of a composed training config that :func:`build` checks, and the seed and
    the checkpoint it starts from: what can be told wrong before anything is built (Hydra's
    config too, before Hydra makes the run folder)."""
    check_arguments(cfg)
    check_optimizer(cfg.get("lit"))
    check_scheduler(cfg.get("lit"))
    check_trainer(cfg)
    check_matmul_precision(cfg.get("matmul_precision", "highest"))
    check_seed(cfg.get("seed"))
    check_ckpt_path(cfg.get("ckpt_path"))


def build_trainer(cfg: DictConfig, extra_callbacks=()) -> L.Trainer:
    """The Lightning trainer of ``cfg.trainer`` (its strategy: :func:`strategy_of`) with
    ``cfg.callbacks`` (then ``extra_callbacks``) and ``cfg.logger``, which gets the whole
    config (:func:`~physgnn.training.tracking.log_config`)."""
    check_trainer(cfg)
    callbacks = [instantiate(c) for c in (cfg.get("callbacks") or {}).values()]
    callbacks += list(extra_callbacks)
    logger = instantiate(cfg.logger) if cfg.get("logger") else False
    # The data module shares the pairs out between DDP processes itself (EpochSampler);
    # checkpoints go through a temporary file and a rename (checkpoint_io.py)
    trainer = instantiate(
        cfg.trainer,
        strategy=strategy_of(cfg.trainer),
        callbacks=callbacks,
        logger=logger,
        default_root_dir=str(cfg.run_dir),
        use_distributed_sampler=False,
        plugins=[AtomicCheckpointIO()],
    )
    log_config(trainer.loggers, cfg)
    return trainer


def build(cfg: DictConfig, extra_callbacks=()):
    """``(datamodule, LitSimulator, trainer)`` of a composed training config, every value
    checked before anything is built (:func:`check_config`)."""
    check_config(cfg)
    set_matmul_precision(cfg.get("matmul_precision", "highest"))
    datamodule = instantiate(cfg.datamodule)
    simulator = instantiate(cfg.model, stats=datamodule.stats())
    datamodule.engine_state = simulator.inputs.engine_state  # the pairs carry the model's state
    simulator.effects_trained.copy_(datamodule.effects_trained())
    lit = instantiate(cfg.lit, simulator=simulator, optimizer=_optimizer(cfg))
    return datamodule, lit, build_trainer(cfg, extra_callbacks)


MATMUL_PRECISIONS = ("highest", "high", "medium")


def check_matmul_precision(value: str) -> None:
    """``matmul_precision`` is one of :data:`MATMUL_PRECISIONS`, else one line."""
    if value not in MATMUL_PRECISIONS:
        raise ConfigError(
            f"matmul_precision must be one of {list(MATMUL_PRECISIONS)}, got {value!r}"
        )


def set_matmul_precision(value: str) -> None:
    """``torch.set_float32_matmul_precision``: ``high`` lets fp32 matrix products use TF32 on
    GPUs that have it; a one-line error for another value."""
    check_matmul_precision(value)
    torch.set_float32_matmul_precision(value)


def _optimizer(cfg: DictConfig):
    """``lit.optimizer``, not fused under mixed precision: Lightning clips the gradients of a
    fused optimizer only at full precision (it would stop the run)."""
    node = cfg.lit.optimizer
    mixed = str(cfg.trainer.get("precision", "32-true")).endswith("mixed")
    if mixed and node.get("fused"):
        log.info("trainer.precision=%s: the optimizer runs without fused", cfg.trainer.precision)
        node = OmegaConf.merge(node, {"fused": False})
    return instantiate(node)
