"""A training run on disk: ``<run_dir>/run.json``, ``.hydra/config.yaml`` and
``checkpoints/{best-*,last}.ckpt``; :func:`load_run` rebuilds its trained simulator.

No Lightning here: evaluation loads runs without importing the trainer.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import PhysgnnError
from physgnn.files import write_json
from physgnn.models.learned import LearnedSimulator

RUN_JSON = "run.json"
# The trained simulator shipped with physgnn, a run folder of weights only
# (physgnn/training/export.py); ``run=pretrained`` names it wherever a run folder is taken.
PRETRAINED = "pretrained"
PRETRAINED_DIR = Path(__file__).resolve().parents[1] / "pretrained"
# The layout of an exported run's weights; a run of another layout is refused in one line.
WEIGHTS_FORMAT = 1
# Model targets of runs trained before the package was split into subpackages.
MOVED_TARGETS = {"physgnn.simulator.LearnedSimulator": "physgnn.models.learned.LearnedSimulator"}


class RunError(PhysgnnError, ValueError):
    """A run folder's weights cannot be loaded by this physgnn (one-line message)."""


def resolve_run(run: str | Path) -> Path:
    """The run folder ``run`` names: the shipped weights for ``pretrained`` (a one-line error
    where this checkout has none), else the path."""
    if str(run) != PRETRAINED:
        return Path(run)
    if not (PRETRAINED_DIR / RUN_JSON).is_file():
        raise RunError(
            "run=pretrained: this checkout ships no trained weights yet (physgnn/pretrained is "
            "empty); train a model (make train) and pass run=<its run folder>"
        )
    return PRETRAINED_DIR


def write_run_json(run_dir: str | Path, info: dict) -> Path:
    """``run.json`` of a run (status, experiment, overrides, seed, figures), atomically."""
    return write_json(Path(run_dir) / RUN_JSON, info)


def read_run_json(run_dir: str | Path) -> dict:
    """``run.json`` of a run; ``{}`` when there is none."""
    path = Path(run_dir) / RUN_JSON
    return json.loads(path.read_text()) if path.exists() else {}


def run_status(run_dir: Path) -> str:
    """``status`` of a run's run.json (``"unreadable"`` when it cannot be read)."""
    try:
        return str(json.loads((Path(run_dir) / RUN_JSON).read_text()).get("status"))
    except (OSError, ValueError):
        return "unreadable"


def checkpoint_of(run_dir: Path) -> Path:
    """The best checkpoint of a run, else its last one. Several ``best-*`` files (a run
    resumed after its folder moved: Lightning then forgets the best score so far and keeps
    the earlier file) are told apart by the score each was saved with (the latest on a tie
    or where none is found)."""
    best = sorted((run_dir / "checkpoints").glob("best-*.ckpt"))
    last = run_dir / "checkpoints" / "last.ckpt"
    if len(best) > 1:
        return min(enumerate(best), key=lambda item: (_own_score(item[1]), -item[0]))[1]
    if best:
        return best[-1]
    if last.exists():
        return last
    raise FileNotFoundError(
        f"no checkpoint in {run_dir / 'checkpoints'} (did the run finish an epoch?)"
    )


def _own_score(path: Path) -> float:
    """The monitored score a checkpoint was saved with, lower is better (ModelCheckpoint's
    ``current_score``; negated for ``mode='max'``); +inf where it holds none."""
    try:
        callbacks = torch.load(path, map_location="cpu", weights_only=False).get("callbacks", {})
    except (OSError, RuntimeError, AttributeError):
        return float("inf")
    for key, state in callbacks.items():
        score = state.get("current_score") if isinstance(state, dict) else None
        if str(key).startswith("ModelCheckpoint") and score is not None:
            return -float(score) if "'mode': 'max'" in str(key) else float(score)
    return float("inf")


# Model keys that runs of an earlier physgnn lack, with the values their model had (the
# invariance changes: physgnn/models/learned.py); the defaults of these keys changed since.
EARLIER_MODEL = {"relative_pairs": False, "mass_ratio": False, "aggregation": "sum",
                 "rest_decision": False}  # fmt: skip


def load_run(run_dir: str | Path) -> tuple[LearnedSimulator, DictConfig, dict]:
    """``(simulator, cfg, info)`` of a finished run (or ``pretrained``): the simulator from
    ``.hydra/config.yaml`` and the best (else last) checkpoint, in eval mode on the CPU;
    ``info`` is run.json (plus ``checkpoint``, the file loaded). Weights of another format or
    that do not fit the model this physgnn builds from the config are refused in one line."""
    run_dir = resolve_run(run_dir)
    config = run_dir / ".hydra" / "config.yaml"
    if not config.exists():
        raise FileNotFoundError(f"{run_dir} is not a training run (no .hydra/config.yaml)")
    info = read_run_json(run_dir)
    _check_format(run_dir, info.get("weights_format", WEIGHTS_FORMAT))
    cfg = OmegaConf.load(config)
    cfg.run_dir = str(run_dir)
    target = OmegaConf.select(cfg, "model._target_")
    if target in MOVED_TARGETS:
        cfg.model._target_ = MOVED_TARGETS[target]
    for key, value in EARLIER_MODEL.items():  # a run of an earlier physgnn: its own model
        if key not in cfg.model:
            cfg.model[key] = value
    path = checkpoint_of(run_dir)
    state = torch.load(path, map_location="cpu", weights_only=True)["state_dict"]
    state = {
        k.removeprefix("simulator."): v for k, v in state.items() if k.startswith("simulator.")
    }
    simulator = instantiate(cfg.model, stats=LearnedSimulator.stats_from_state_dict(state))
    try:
        simulator.load_state_dict(state)
    except RuntimeError as err:
        reason = str(err).split("\n\t")[1].strip() if "\n\t" in str(err) else str(err)
        raise RunError(
            f"{path} does not fit the model this physgnn builds from {config} ({reason[:160]}): "
            "it was trained by another version; train it again or use weights of this version"
        ) from err
    simulator.eval()
    info["checkpoint"] = str(path)
    return simulator, cfg, info


def _check_format(run_dir: Path, found) -> None:
    if found != WEIGHTS_FORMAT:
        raise RunError(
            f"{run_dir} holds weights of format {found}; this physgnn reads format "
            f"{WEIGHTS_FORMAT}: export the run again with this version (make ship RUN=...)"
        )
