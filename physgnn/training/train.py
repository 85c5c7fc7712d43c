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
from lightning.pytorch.callbacks import Timer
from lightning.pytorch.utilities.rank_zero import rank_zero_only
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError, Interrupted, one_line, signal_name
from physgnn.files import code_commit, write_text
from physgnn.ranges import check_seed
from physgnn.training.build import build
from physgnn.training.datamodule import dataset_identity
from physgnn.training.finite import NonFiniteLossError
from physgnn.training.progress import RunProgress, StopOnSignal, StopTraining, save_last
from physgnn.training.quiet import quiet_lightning
from physgnn.training.resume_checks import check_checkpoint, check_run_dir, resume_from
from physgnn.training.runlog import run_log
from physgnn.training.runs import write_run_json

log = logging.getLogger(__name__)


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
        "dataset": dataset_identity(
            str(OmegaConf.select(cfg, "datamodule.data_dir")),
            str(OmegaConf.select(cfg, "datamodule.preset")),
        ),
        "run_dir": str(run_dir),
        "resumed_from": None,
        "started": datetime.now().isoformat(timespec="seconds"),
        "host": socket.gethostname(),
        "pid": os.getpid(),
        # CPU results are reproducible for a seed, a thread count and the code: record them.
        "threads": torch.get_num_threads(),
        "commit": code_commit(),
    }


def train(cfg: DictConfig) -> dict:
    """Train ``cfg.model`` on ``cfg.datamodule``; returns the run's summary (also run.json)."""
    quiet_lightning()
    _log_to_run_file()
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    # before run.json is written: the folder may be another run's, or the user's
    check_run_dir(cfg, run_dir, _overrides() if HydraConfig.initialized() else None)
    with run_log(run_dir):
        return _train(cfg, run_dir)


def val_loss(cfg: DictConfig) -> float | None:
    """:func:`train`, returning its final validation loss (what ``python -m physgnn.train``
    returns: the value a Hydra sweeper optimises)."""
    return train(cfg)["val_loss"]


def _train(cfg: DictConfig, run_dir: Path) -> dict:
    """:func:`train` in ``run_dir``, once it may train there; run.json records how it ends."""
    _keep_config(cfg, run_dir)
    info = _start(cfg, run_dir)
    progress, stop, trainer = RunProgress(), StopOnSignal(), None
    stop.install()
    try:
        ckpt_path = info["resumed_from"] = resume_from(cfg, run_dir)
        _record(run_dir, info)
        log.info(
            "training %s in %s%s",
            cfg.experiment_name,
            run_dir,
            f", resuming from {ckpt_path}" if ckpt_path else "",
        )
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
