"""``python -m physgnn.train [overrides]``: train a learned simulator (Hydra + Lightning).

``train(cfg)`` does the work and returns the final metrics; ``main`` is the Hydra wrapper that
turns configuration and data errors into one line ``error: ...`` (exit status 2). A run writes
``<run_dir>/checkpoints/{last,best-*}.ckpt``, its logs and ``<run_dir>/run.json``;
``load_run(run_dir)`` rebuilds the trained simulator for evaluation.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import hydra
import lightning as L
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from physgnn import CONF_DIR
from physgnn.dataset import DatasetError
from physgnn.lit import NonFiniteLossError
from physgnn.scene import SceneError
from physgnn.simulator import LearnedSimulator, StatsError

NUMERIC_TRAINER_KEYS = ("max_epochs", "max_steps", "gradient_clip_val", "log_every_n_steps")


class ConfigError(ValueError):
    """A config value of the wrong kind (one-line message)."""


USER_ERRORS = (
    DatasetError,
    SceneError,
    StatsError,
    ConfigError,
    HydraException,
    OmegaConfBaseException,
)


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
        _write_json(run_dir / "run.json", info)
        raise
    elapsed = time.perf_counter() - start
    _save_final(trainer)
    info.update(
        # interrupted (Ctrl-C): resumable from checkpoints/last.ckpt, not evaluated
        status="interrupted" if trainer.interrupted else "finished",
        train_time_s=elapsed,
        epochs=int(trainer.current_epoch),
        max_epochs=trainer.max_epochs,
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
    _write_json(run_dir / "run.json", info)
    return info


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


def _write_json(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    tmp.replace(path)


def _checkpoint_of(run_dir: Path) -> Path:
    best = sorted((run_dir / "checkpoints").glob("best-*.ckpt"))
    last = run_dir / "checkpoints" / "last.ckpt"
    if best:
        return best[-1]
    if last.exists():
        return last
    raise FileNotFoundError(
        f"no checkpoint in {run_dir / 'checkpoints'} (did the run finish an epoch?)"
    )


def load_run(run_dir: str | Path) -> tuple[LearnedSimulator, DictConfig, dict]:
    """``(simulator, cfg, info)`` of a finished run: the simulator from ``.hydra/config.yaml``
    and the best (else last) checkpoint, in eval mode on the CPU; ``info`` is run.json (plus
    ``checkpoint``, the file loaded)."""
    run_dir = Path(run_dir)
    config = run_dir / ".hydra" / "config.yaml"
    if not config.exists():
        raise FileNotFoundError(f"{run_dir} is not a training run (no .hydra/config.yaml)")
    cfg = OmegaConf.load(config)
    cfg.run_dir = str(run_dir)
    path = _checkpoint_of(run_dir)
    state = torch.load(path, map_location="cpu", weights_only=True)["state_dict"]
    state = {
        k.removeprefix("simulator."): v for k, v in state.items() if k.startswith("simulator.")
    }
    simulator = instantiate(cfg.model, stats=LearnedSimulator.stats_from_state_dict(state))
    simulator.load_state_dict(state)
    simulator.eval()
    info = json.loads((run_dir / "run.json").read_text()) if (run_dir / "run.json").exists() else {}
    info["checkpoint"] = str(path)
    return simulator, cfg, info


def _one_line(err: Exception) -> str:
    return "; ".join(line.strip() for line in str(err).splitlines() if line.strip())


# An absolute path: "../conf" fails when main() is imported (console script, tests).
@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="train")
def main(cfg: DictConfig) -> float | None:
    try:
        return train(cfg)["val_loss"]
    except USER_ERRORS as err:
        print(f"error: {_one_line(err)}", file=sys.stderr)
        sys.exit(2)
    except NonFiniteLossError as err:
        print(
            f"error: {err}; last good checkpoint kept in {Path(cfg.run_dir) / 'checkpoints'}",
            file=sys.stderr,
        )
        sys.exit(1)


if __name__ == "__main__":
    main()
