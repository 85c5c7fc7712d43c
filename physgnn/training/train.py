"""``python -m physgnn.train [overrides]``: train a learned simulator (Hydra + Lightning).

``train(cfg)`` does the work and returns the final metrics. A run writes
``<run_dir>/checkpoints/{last,best-*}.ckpt``, its logs and ``<run_dir>/run.json``;
:func:`physgnn.training.runs.load_run` rebuilds the trained simulator for evaluation.
"""

from __future__ import annotations

import time
from pathlib import Path

import lightning as L
from hydra.core.hydra_config import HydraConfig
from hydra.utils import instantiate
from lightning.pytorch.callbacks import Timer
from omegaconf import DictConfig

from physgnn.errors import ConfigError
from physgnn.training.lit import NonFiniteLossError
from physgnn.training.runs import write_run_json

NUMERIC_TRAINER_KEYS = ("max_epochs", "max_steps", "gradient_clip_val", "log_every_n_steps")


def check_trainer_config(trainer_cfg: DictConfig) -> None:
    """Catch a non-numeric value before Lightning fails on it deep inside ``fit``."""
    for key in NUMERIC_TRAINER_KEYS:
        value = trainer_cfg.get(key)
        if value is not None and not isinstance(value, int | float):
            raise ConfigError(f"trainer.{key} must be a number, got {value!r}")


def build_trainer(cfg: DictConfig) -> L.Trainer:
    """The Lightning trainer of ``cfg.trainer`` with ``cfg.callbacks`` and ``cfg.logger``."""
    check_trainer_config(cfg.trainer)
    callbacks = [instantiate(c) for c in (cfg.get("callbacks") or {}).values()]
    logger = instantiate(cfg.logger) if cfg.get("logger") else False
    return instantiate(
        cfg.trainer, callbacks=callbacks, logger=logger, default_root_dir=str(cfg.run_dir)
    )


def build(cfg: DictConfig):
    """``(datamodule, LitSimulator, trainer)`` of a composed training config."""
    datamodule = instantiate(cfg.datamodule)
    simulator = instantiate(cfg.model, stats=datamodule.stats())
    simulator.effects_trained.copy_(datamodule.effects_trained())
    lit = instantiate(cfg.lit, simulator=simulator)
    return datamodule, lit, build_trainer(cfg)


def _overrides() -> list[str]:
    return list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else []


def _metric(trainer: L.Trainer, name: str) -> float | None:
    value = trainer.callback_metrics.get(name)
    return None if value is None else float(value)


def _checkpoints(trainer: L.Trainer) -> dict:
    ckpt = trainer.checkpoint_callback
    if ckpt is None:
        return {"best": None, "last": None}
    return {"best": ckpt.best_model_path or None, "last": ckpt.last_model_path or None}


def train(cfg: DictConfig) -> dict:
    """Train ``cfg.model`` on ``cfg.datamodule``; returns the run's summary (also run.json)."""
    L.seed_everything(cfg.seed, workers=True)
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    datamodule, lit, trainer = build(cfg)
    info = {
        "status": "running",
        "experiment": cfg.experiment_name,
        "overrides": _overrides(),
        "seed": int(cfg.seed),
        "run_dir": str(run_dir),
    }
    start = time.perf_counter()
    try:
        trainer.fit(lit, datamodule=datamodule, ckpt_path=cfg.get("ckpt_path"))
    except NonFiniteLossError as err:
        info.update(status="diverged", error=str(err), checkpoints=_checkpoints(trainer))
        write_run_json(run_dir, info)
        kept = run_dir / "checkpoints"
        raise NonFiniteLossError(f"{err}; last good checkpoint kept in {kept}") from err
    elapsed = time.perf_counter() - start
    _save_final(trainer)
    info.update(
        status=_final_status(trainer),
        train_time_s=elapsed,
        epochs=int(trainer.current_epoch),
        max_epochs=trainer.max_epochs,
        max_steps=trainer.max_steps,
        global_step=int(trainer.global_step),
        pairs_seen=lit.pairs_seen,
        pairs_per_s=lit.pairs_seen / elapsed,
        nodes_per_s=lit.nodes_seen / elapsed,
        train_loss=_metric(trainer, "train/loss"),
        train_loss_mse=_metric(trainer, "train/loss_mse"),
        val_loss=_metric(trainer, "val/loss"),
        val_loss_energy=_metric(trainer, "val/loss_energy"),
        checkpoints=_checkpoints(trainer),
    )
    write_run_json(run_dir, info)
    return info


def _final_status(trainer: L.Trainer) -> str:
    """``interrupted`` (Ctrl-C: resumable from checkpoints/last.ckpt, not evaluated),
    ``truncated`` (a step budget cut short by ``trainer.max_time``: evaluated, flagged) or
    ``finished``."""
    if trainer.interrupted:
        return "interrupted"
    timers = [c for c in trainer.callbacks if isinstance(c, Timer)]
    if timers and timers[0].time_remaining() <= 0:
        return "truncated"
    return "finished"


def _save_final(trainer: L.Trainer) -> None:
    """Save ``last.ckpt`` again when training stopped after its last save (time limit
    reached mid-epoch, Ctrl-C), so it always holds the final weights."""
    ckpt = trainer.checkpoint_callback
    if ckpt is None or not ckpt.dirpath or trainer.fast_dev_run:
        return
    if getattr(ckpt, "_last_global_step_saved", -1) != trainer.global_step:
        last = Path(ckpt.dirpath) / "last.ckpt"
        trainer.save_checkpoint(last)
        ckpt.last_model_path = str(last)
