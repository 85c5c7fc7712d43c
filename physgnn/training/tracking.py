"""What the loggers (csv, TensorBoard, wandb) learn of a run: its whole config, resolved, and
a name that tells the runs of a sweep apart.

``run_name`` (``conf/train.yaml``: ``${physgnn_run_name:${experiment_name}}``) is the
experiment and the job's overrides in their order on the command line (a sweep's keys first
where given first), each key by its last two parts: ``baseline`` with ``model.network.M=3
seed=1`` is ``baseline_network.M=3_seed=1``, in characters a file name
takes (TensorBoard's run folder, wandb's run name; the experiment is wandb's group); past
:data:`NAME_CHARS`, its end is a hash of the whole, so that runs stay apart. The overrides
left out of a sweep job's folder name (``hydra.job.config.override_dirname
.exclude_keys``: the experiment, the folders) are left out of it too.
"""

from __future__ import annotations

import hashlib
import re

from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from physgnn.overrides import key_of, parse_overrides

# wandb shows 128 characters of a name; a file name holds 255
NAME_CHARS = 120


def run_name(experiment: str, overrides: list[str] = ()) -> str:
    """``experiment`` and ``overrides`` (``key=value``) as one readable, file-safe name."""
    parts = [str(experiment)]
    for given in parse_overrides(list(overrides)):
        short = ".".join(given.key.split(".")[-2:])
        parts.append(short if given.prefix == "~" else f"{short}={given.written}")
    name = re.sub(r"[^A-Za-z0-9._=+-]+", "-", "_".join(parts))
    if len(name) <= NAME_CHARS:
        return name
    digest = hashlib.sha1(name.encode()).hexdigest()[:8]
    return f"{name[: NAME_CHARS - 9]}-{digest}"


def job_overrides() -> list[str]:
    """The overrides of the running Hydra job that name it (none outside Hydra)."""
    if not HydraConfig.initialized():
        return []
    hydra = HydraConfig.get()
    left_out = set(OmegaConf.select(hydra, "job.config.override_dirname.exclude_keys") or [])
    return [o for o in hydra.overrides.task if key_of(o) not in left_out]


def _job_run_name(experiment: str) -> str:
    return run_name(experiment, job_overrides())


OmegaConf.register_new_resolver("physgnn_run_name", _job_run_name, replace=True)


def resolved(node) -> object:
    """``node`` as plain dicts and lists, every interpolation resolved where it can be (one that
    cannot, ``${hydra:...}`` outside Hydra, stays as written)."""
    if isinstance(node, DictConfig):
        return {str(key): resolved(_value(node, key)) for key in node.keys()}
    if isinstance(node, ListConfig):
        return [resolved(_value(node, index)) for index in range(len(node))]
    return node


def _value(node: DictConfig | ListConfig, key):
    try:
        return node[key]
    except OmegaConfBaseException:
        return node._get_node(key)._value()


def log_config(loggers, cfg: DictConfig) -> None:
    """The whole composed config, resolved, as every logger's hyperparameters (hparams.yaml of
    csv and TensorBoard, wandb's config): the model, data, recipe and trainer of the run."""
    config = resolved(cfg)
    for logger in loggers:
        logger.log_hyperparams(config)
