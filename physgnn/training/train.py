"""``python -m physgnn.train [overrides]``: train a learned simulator (Hydra + Lightning).

``train(cfg)`` does the work and returns the final metrics. A run writes
``<run_dir>/checkpoints/{last,best-*}.ckpt``, its logs and ``<run_dir>/run.json``: ``running``
from the start, then ``finished``, ``truncated`` (time guard), ``interrupted`` (a signal:
:mod:`physgnn.training.progress`), ``diverged``, ``failed`` (with the error) or ``debug`` (a
``fast_dev_run``); :func:`physgnn.training.runs.load_run` rebuilds the trained simulator for
evaluation. Training an interrupted run's folder again resumes it from its ``last.ckpt`` (a
requeued cluster job does so); counters and training time cover the whole run.
"""

from __future__ import annotations

import logging
import os
import socket
from datetime import datetime
from pathlib import Path

import lightning as L
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.utils import instantiate
from lightning.pytorch.callbacks import Timer
from lightning.pytorch.utilities.rank_zero import rank_zero_only
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError, Interrupted, check_seed, one_line, signal_name
from physgnn.files import write_text
from physgnn.training.checkpoint_io import AtomicCheckpointIO
from physgnn.training.checks import (
    check_arguments,
    check_budget,
    check_checkpoint,
    check_monitors,
    check_optimizer,
    check_run_dir,
    resume_from,
)
from physgnn.training.lit import NonFiniteLossError
from physgnn.training.progress import RunProgress, StopOnSignal, StopTraining, save_last
from physgnn.training.runlog import run_log
from physgnn.training.runs import write_run_json
from physgnn.training.schedule import check_scheduler

log = logging.getLogger(__name__)

NUMERIC_TRAINER_KEYS = ("max_epochs", "max_steps", "gradient_clip_val", "log_every_n_steps")


def check_trainer_config(trainer_cfg: DictConfig) -> None:
    """Catch a non-numeric value before Lightning fails on it deep inside ``fit``."""
    for key in NUMERIC_TRAINER_KEYS:
        value = trainer_cfg.get(key)
        if value is not None and not isinstance(value, int | float):
            raise ConfigError(f"trainer.{key} must be a number, got {value!r}")
    if trainer_cfg.get("accelerator") in ("gpu", "cuda") and not torch.cuda.is_available():
        raise ConfigError(
            f"trainer.accelerator={trainer_cfg.accelerator} needs a CUDA GPU and torch sees "
            "none (torch.cuda.is_available() is False): train on the CPU (trainer=cpu, the "
            "default), or on a machine with a GPU and a CUDA build of torch"
        )


def check_trainer(cfg: DictConfig) -> None:
    """The trainer's values and the callbacks' monitors (before Lightning fails on them)."""
    check_trainer_config(cfg.trainer)
    check_budget(cfg.trainer)
    check_monitors(cfg.get("callbacks"))


def build_trainer(cfg: DictConfig, extra_callbacks=()) -> L.Trainer:
    """The Lightning trainer of ``cfg.trainer`` with ``cfg.callbacks`` (then
    ``extra_callbacks``) and ``cfg.logger``."""
    check_trainer(cfg)
    callbacks = [instantiate(c) for c in (cfg.get("callbacks") or {}).values()]
    callbacks += list(extra_callbacks)
    logger = instantiate(cfg.logger) if cfg.get("logger") else False
    root = str(cfg.run_dir)
    # The data module shares the pairs out between DDP processes itself (EpochSampler)
    # Checkpoints go through a temporary file and a rename (checkpoint_io.py)
    return instantiate(cfg.trainer, callbacks=callbacks, logger=logger, default_root_dir=root,
                       use_distributed_sampler=False, plugins=[AtomicCheckpointIO()])  # fmt: skip


def build(cfg: DictConfig, extra_callbacks=()):
    """``(datamodule, LitSimulator, trainer)`` of a composed training config, every value
    checked before anything is built."""
    check_arguments(cfg)
    check_optimizer(cfg.get("lit"))
    check_scheduler(cfg.get("lit"))
    check_trainer(cfg)
    datamodule = instantiate(cfg.datamodule)
    simulator = instantiate(cfg.model, stats=datamodule.stats())
    simulator.effects_trained.copy_(datamodule.effects_trained())
    lit = instantiate(cfg.lit, simulator=simulator)
    return datamodule, lit, build_trainer(cfg, extra_callbacks)


class TrainingInterrupted(Interrupted):
    """Training stopped by a signal; ``last.ckpt`` and run.json say where it stopped."""


def _overrides() -> list[str]:
    return list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else []


def _metric(trainer: L.Trainer, name: str) -> float | None:
    value = trainer.callback_metrics.get(name)
    return None if value is None else float(value)


def _checkpoints(trainer: L.Trainer | None) -> dict:
    ckpt = None if trainer is None else trainer.checkpoint_callback
    if ckpt is None:
        return {"best": None, "last": None}
    return {"best": ckpt.best_model_path or None, "last": ckpt.last_model_path or None}


def _record(run_dir: Path, info: dict) -> None:
    """Write run.json (DDP: the first process only)."""
    if rank_zero_only.rank == 0:
        write_run_json(run_dir, info)


def _log_to_run_file() -> None:
    """Under Hydra, let Lightning's messages reach Hydra's log handlers (the console and
    ``<run_dir>/train.log``): when imported, Lightning gave its logger a console handler of
    its own and cut it off from the root logger."""
    if HydraConfig.initialized() and logging.getLogger().handlers:
        for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
            logger = logging.getLogger(name)
            for handler in list(logger.handlers):
                logger.removeHandler(handler)
            logger.propagate = True


def _keep_config(cfg: DictConfig, run_dir: Path) -> None:
    """``run_dir/.hydra/config.yaml``, what :func:`physgnn.training.runs.load_run` reads, when
    Hydra wrote it elsewhere (``run_dir=`` apart from Hydra's output folder, or no Hydra)."""
    path = run_dir / ".hydra" / "config.yaml"
    if not path.exists():
        write_text(path, OmegaConf.to_yaml(cfg))


def _start(cfg: DictConfig, run_dir: Path) -> dict:
    """run.json of a run that starts (``resumed_from`` is filled in once known)."""
    return {
        "status": "running",
        "experiment": cfg.experiment_name,
        "overrides": _overrides(),
        "seed": cfg.seed,
        "run_dir": str(run_dir),
        "resumed_from": None,
        "started": datetime.now().isoformat(timespec="seconds"),
        "host": socket.gethostname(),
        "pid": os.getpid(),
        # CPU results are reproducible for a seed *and* a thread count: record it.
        "threads": torch.get_num_threads(),
    }


def train(cfg: DictConfig) -> dict:
    """Train ``cfg.model`` on ``cfg.datamodule``; returns the run's summary (also run.json)."""
    _log_to_run_file()
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    # before run.json is written: the folder may be another run's, or the user's
    check_run_dir(cfg, run_dir, _overrides() if HydraConfig.initialized() else None)
    with run_log(run_dir):
        return _train(cfg, run_dir)


def _train(cfg: DictConfig, run_dir: Path) -> dict:
    """:func:`train` in ``run_dir``, once it may train there; run.json records how it ends."""
    _keep_config(cfg, run_dir)
    info = _start(cfg, run_dir)
    progress, stop, trainer = RunProgress(), StopOnSignal(), None
    stop.install()
    try:
        ckpt_path = info["resumed_from"] = resume_from(cfg, run_dir)
        _record(run_dir, info)
        log.info("training %s in %s%s", cfg.experiment_name, run_dir,
                 f", resuming from {ckpt_path}" if ckpt_path else "")  # fmt: skip
        check_seed(cfg.seed)
        L.seed_everything(cfg.seed, workers=True)
        datamodule, lit, trainer = build(cfg, [progress, stop])
        resumed_step = check_checkpoint(ckpt_path, lit, cfg.get("model"))
        trainer.fit(lit, datamodule=datamodule, ckpt_path=ckpt_path)
        save_last(trainer)
        if ckpt_path and trainer.global_step == resumed_step:
            raise ConfigError(
                f"nothing to train: {ckpt_path} already reached trainer.max_epochs="
                f"{trainer.max_epochs} (step {resumed_step}); raise trainer.max_epochs to go on"
            )
    except BaseException as err:
        stop.restore()
        info.update(_figures(trainer, progress))
        outcome = _stopped(err, run_dir, info, stop)
        if outcome is err:
            raise
        raise outcome from err
    stop.restore()
    info.update(status=_final_status(trainer), **_figures(trainer, progress))
    _record(run_dir, info)
    log.info("run %s: %s after %d steps", run_dir, info["status"], info["global_step"])
    return info


def _figures(trainer: L.Trainer | None, progress: RunProgress) -> dict:
    """Counters (whole run), losses and checkpoints for run.json."""
    if trainer is None:
        return {}
    seconds = progress.seconds()
    return dict(
        train_time_s=seconds,
        sessions=progress.sessions,
        epochs=int(trainer.current_epoch),
        max_epochs=trainer.max_epochs,
        max_steps=trainer.max_steps,
        global_step=int(trainer.global_step),
        pairs_seen=progress.pairs_seen,
        pairs_per_s=progress.pairs_seen / seconds if seconds > 0 else None,
        nodes_per_s=progress.nodes_seen / seconds if seconds > 0 else None,
        train_loss=_metric(trainer, "train/loss"),
        train_loss_mse=_metric(trainer, "train/loss_mse"),
        val_loss=_metric(trainer, "val/loss"),
        val_loss_energy=_metric(trainer, "val/loss_energy"),
        checkpoints=_checkpoints(trainer),
    )


def _stopped(err: BaseException, run_dir: Path, info: dict, stop: StopOnSignal):
    """Record how the run ended in run.json; returns the exception to raise (``err`` itself
    for a bug, which keeps its traceback)."""
    last = (info.get("checkpoints") or {}).get("last")
    kept = f"last checkpoint {last}" if last else "no checkpoint was saved"
    if isinstance(err, StopTraining):
        info.update(status="interrupted", error=f"stopped by {signal_name(err.signum)}")
        outcome = TrainingInterrupted(
            f"training stopped by {signal_name(err.signum)} at step {info.get('global_step')}; "
            f"{kept}; run.json says interrupted. Resume: python -m physgnn.train "
            f"run_dir={run_dir} (same overrides)",
            err.signum,
        )
    elif isinstance(err, KeyboardInterrupt | SystemExit):  # a second Ctrl-C, or Lightning's
        info.update(status="interrupted", error="stopped at once")
        outcome = TrainingInterrupted(f"training stopped at once; {kept}")
    elif isinstance(err, NonFiniteLossError):
        info.update(status="diverged", error=str(err))
        outcome = NonFiniteLossError(f"{err}; {kept}")
    else:
        info.update(status="failed", error=f"{type(err).__name__}: {one_line(err)}")
        outcome = err
    try:
        _record(run_dir, info)
    except OSError as record_err:  # a full disk: the error that stopped the run comes first
        log.error("run %s: run.json could not be written (%s)", run_dir, record_err)
    log.error("run %s: %s (%s)", run_dir, info["status"], info["error"])
    if isinstance(err, StopTraining):
        stop.chain()  # a scheduler's pre-emption handler: it requeues the job and exits
    return outcome


def _final_status(trainer: L.Trainer) -> str:
    """``debug`` (a ``fast_dev_run``: not a trained model), ``truncated`` (a step budget cut
    short by ``trainer.max_time``: evaluated, flagged) or ``finished``."""
    if trainer.fast_dev_run:
        return "debug"
    timers = [c for c in trainer.callbacks if isinstance(c, Timer)]
    if timers and timers[0].time_remaining() <= 0:
        return "truncated"
    return "finished"
