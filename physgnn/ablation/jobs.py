"""The jobs of the ablation study: every unique configuration of the sweeps × the seeds.

A sweep is a file ``conf/experiment/<name>.yaml`` whose ``hydra.sweeper.params`` list the values
of each key (``model.H: 0,1,2,3,4``; ``seed`` is the study's, not the file's). Each combination
is composed with ``conf/train.yaml`` and reduced to what it changes from the default training:
``+variant=m1`` and ``model.network.M=1`` both become ``model.network.M=1``, and every sweep's
default value becomes the one ``baseline``, so each configuration is trained once per seed
however many sweeps name it. :class:`Config` keeps, per sweep, the value the sweep plots it at.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from physgnn import CONF_DIR
from physgnn.cli import compose_config
from physgnn.errors import PhysgnnError
from physgnn.overrides import parse_overrides
from physgnn.training.layout import flat_layout

BASELINE = "baseline"
# The parts of the training config that make a configuration (the rest is where and how long).
IDENTITY = ("model", "lit", "datamodule", "data")
RUN_LENGTH_DECAY = "physgnn.training.schedule.RunLengthDecay"
EXPONENTIAL_LR = "torch.optim.lr_scheduler.ExponentialLR"
# Keys that vary with the seed or the folder, never with the configuration.
IGNORED = {"seed", "data_dir", "dir", "preset", "name"}
# How a run executes, not what it trains: how the network is compiled, whether graphs have a
# fixed capacity (the same edges, masked; model keys in the flat layout), whether passes after
# a rebuild recompute only what changed (the same numbers), the rollout guards (the energy
# guard, the friction cone, a consistent rest: rollouts only, the training steps are the same)
# and how much the validation rollouts (which choose best.ckpt, like the callbacks) roll out.
EXECUTION = (
    "lit.compile_mode",
    "lit.compile_shapes",
    "model.fixed_capacity",
    "model.incremental_passes",
    "model.energy_guard",
    "model.energy_slack",
    "model.friction_cone",
    "model.rest_consistent",
    "data.val_rollout.",
)
# Keys added since the study's records began, left out of the fingerprint while they hold the
# value every earlier default had: the same model keeps its fingerprint.
ADDED_AT_EARLIER_VALUE = {
    "model.engine_state": False,
    "model.plane_floor": False,
    "model.plane_newton": False,
    "model.pair_floor": False,
    "model.pair_newton": False,
    "lit.loss.event_share": 0.0,
    "lit.loss.event_speed": 0.05,
}


class StudyError(PhysgnnError, ValueError):
    """A study config mistake (unknown sweep, a budget that does not divide)."""


@dataclass
class Config:
    """One unique training configuration: ``key`` (its changes from the default,
    ``"model.network.M=1"``, or ``baseline``), ``overrides`` (the first sweep's, as given to
    ``physgnn.train``), ``points`` (``{sweep: x}``: where each sweep plots it) and ``aliases``
    (``{sweep: [x, ...]}``: further points of one sweep that are this same configuration, e.g.
    the variant ``h0`` where the default's history is already H = 0)."""

    key: str
    overrides: list[str]
    points: dict[str, str] = field(default_factory=dict)
    aliases: dict[str, list[str]] = field(default_factory=dict)


@dataclass(frozen=True)
class Job:
    """One training of the study: a configuration at one seed."""

    config: Config
    seed: int

    @property
    def name(self) -> str:
        return f"{self.config.key} seed={self.seed}"


def sweep_points(name: str) -> list[list[str]]:
    """Every combination of ``conf/experiment/<name>.yaml``'s sweep values but the seed, as
    override lists (``[["model.H=0"], ["model.H=1"], ...]``)."""
    path = Path(CONF_DIR) / "experiment" / f"{name}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in path.parent.glob("*.yaml"))
        raise StudyError(f"no sweep '{name}' (conf/experiment/{name}.yaml); known: {known}")
    params = OmegaConf.select(OmegaConf.load(path), "hydra.sweeper.params") or {}
    axes = [
        [f"{key}={value.strip()}" for value in str(values).split(",")]
        for key, values in params.items()
        if key != "seed"
    ]
    return [list(combo) for combo in itertools.product(*axes)]


def _flat(cfg: DictConfig) -> dict[str, object]:
    """``{dotted key: value}`` of the configuration-making parts of a composed config."""
    out = {}

    def walk(prefix: str, node) -> None:
        if isinstance(node, dict):
            for k, v in node.items():
                if k not in IGNORED:
                    walk(f"{prefix}.{k}" if prefix else str(k), v)
        elif isinstance(node, float) and node.is_integer():
            out[prefix] = int(node)  # λ = 10 and 10.0 are one configuration
        else:
            out[prefix] = node

    for part in IDENTITY:  # unresolved: datamodule.H stays ${model.H}, not a second change
        walk(part, OmegaConf.to_container(cfg[part], resolve=False))
    return out


def config_key(changes: dict[str, object]) -> str:
    """``"k=v k=v"`` sorted, or ``baseline`` for no change."""
    if not changes:
        return BASELINE
    return " ".join(f"{k}={v}" for k, v in sorted(changes.items()))


def study_configs(sweeps: list[str]) -> list[Config]:
    """The unique configurations of ``sweeps``, baseline first, then in sweep order."""
    base = _flat(compose_config("train"))
    configs: dict[str, Config] = {}
    for sweep in sweeps:
        for overrides in sweep_points(sweep):
            flat = _flat(compose_config("train", overrides))
            changes = {k: v for k, v in flat.items() if base.get(k) != v}
            changes |= {k: None for k in base if k not in flat}
            key = config_key(changes)
            config = configs.setdefault(key, Config(key, [] if not changes else overrides))
            point = " ".join(o.written for o in parse_overrides(overrides))
            if sweep in config.points:
                config.aliases.setdefault(sweep, []).append(point)
            else:
                config.points[sweep] = point
    ordered = sorted(configs.values(), key=lambda c: c.key != BASELINE)
    return ordered


def study_jobs(configs: list[Config], seeds: list[int]) -> list[Job]:
    """The baseline's seeds first (every verdict compares to them), then sweep by sweep (a
    configuration under the first sweep that names it), seed by seed within a sweep: the first
    sweep's rows (Table 2) have every seed before the next sweep starts, and a study cut short
    has covered each configuration of a sweep before it repeats any."""
    order: dict[str, list[Config]] = {}
    for config in configs:
        if config.key != BASELINE:
            order.setdefault(next(iter(config.points), ""), []).append(config)
    baseline = [Job(c, int(seed)) for seed in seeds for c in configs if c.key == BASELINE]
    return baseline + [
        Job(config, int(seed)) for group in order.values() for seed in seeds for config in group
    ]


def defaults_fingerprint(train_cfg: DictConfig) -> str:
    """Ten hex digits naming the configuration-making parts of a composed training config: the
    default model and recipe every study key is a change from. A study's records carry it, so
    runs of an earlier default are never mistaken for the current one's. Model keys count in
    the flat layout (:func:`~physgnn.training.layout.flat_layout`): the fingerprint names the
    model, not where its config spells each key."""
    keys = {k: v for k, v in flat_layout(_flat(train_cfg)).items() if not k.startswith(EXECUTION)}
    keys = {k: v for k, v in keys.items() if ADDED_AT_EARLIER_VALUE.get(k, ...) != v}
    text = json.dumps(_per_epoch_decay(keys, train_cfg.trainer), sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def _per_epoch_decay(keys: dict, trainer) -> dict:
    """``keys`` with a run-length decay over epochs written as the per-epoch decay it is
    (``ExponentialLR``, ``gamma`` to 12 digits): one schedule, one fingerprint, however its
    config spells it."""
    if keys.get("lit.scheduler._target_") != RUN_LENGTH_DECAY or trainer.get("max_steps", -1) > 0:
        return keys
    factor = keys.pop("lit.scheduler.final_lr_factor")
    gamma = round(float(factor) ** (1 / int(trainer.max_epochs)), 12)
    return keys | {"lit.scheduler._target_": EXPONENTIAL_LR, "lit.scheduler.gamma": gamma}


def study_budget(cfg: DictConfig) -> dict:
    """What makes a study's runs comparable, stored in every record: ``cfg.budget`` plus
    ``defaults`` (:func:`defaults_fingerprint` of this code's default training, or
    ``cfg.fingerprint`` where set: the records of an earlier default, for its page only)."""
    budget = OmegaConf.to_container(cfg.budget, resolve=True)
    return budget | {"defaults": cfg.get("fingerprint") or current_fingerprint()}


def current_fingerprint() -> str:
    """:func:`defaults_fingerprint` of this code's default training."""
    return defaults_fingerprint(compose_config("train"))


def budget_overrides(budget: DictConfig) -> list[str]:
    """Training overrides of the study's budget: ``steps`` optimiser steps of ``batch_size``
    pairs, in epochs of ``steps_per_epoch`` steps (validation and checkpoints), the clock
    ``max_time`` only a guard; ``extra``: further overrides of every run."""
    steps, per_epoch = int(budget.steps), int(budget.steps_per_epoch)
    if steps < 1 or per_epoch < 1 or steps % per_epoch:
        raise StudyError(
            f"budget.steps ({steps}) must be a positive multiple of budget.steps_per_epoch "
            f"({per_epoch})"
        )
    return [
        f"datamodule.batch_size={int(budget.batch_size)}",
        f"datamodule.pairs_per_epoch={int(budget.batch_size) * per_epoch}",
        f"trainer.max_epochs={steps // per_epoch}",
        f"trainer.max_time={budget.max_time}",
        *[str(o) for o in budget.get("extra") or []],
    ]
