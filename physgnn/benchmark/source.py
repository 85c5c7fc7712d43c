"""The learned model the bench times: the trained model of ``run`` (a run folder or
``pretrained``, loaded by :func:`physgnn.training.runs.load_run`) or, with ``run: null``, the
bench's ``model`` with random weights; and its variants (random weights of the same
architecture, other knobs of the same trained weights).

One source for every learned row of the inference phases (the learned sizes, the interleaved
rounds, the rollout frame, batching, activity and the crossover): each asks :class:`Source`
for a simulator of ``weights: trained`` (the run's, its own statistics and contacts) or
``weights: random`` (the same architecture, ``overrides`` on it, random weights and the
bench data's statistics: what an architecture change costs).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError
from physgnn.training.runs import load_run

TRAINED, RANDOM = "trained", "random"


class BenchError(ConfigError):
    """A bench setting that cannot be run (one-line message)."""


def make_simulator(model_cfg: DictConfig, overrides: dict, stats: dict):
    """The model of ``model_cfg`` with ``overrides`` (constructor keys), random weights."""
    cfg = OmegaConf.merge(model_cfg, overrides)
    sim = instantiate(cfg, stats=stats).eval()
    sim.effects_trained.fill_(True)  # as if trained on every effect: no rollout warning
    return sim


@dataclass
class Source:
    """``model``: the model config of every learned row (the run's, else the bench's);
    ``trained``: the run's simulator (None with ``run: null``); ``label``: what the rows say
    of the weights (the run, or ``random weights``); ``stats``: the bench data's statistics
    (random weights)."""

    model: DictConfig
    trained: object | None
    label: str
    stats: dict

    def simulator(self, weights: str = TRAINED, overrides: dict | None = None):
        """A fresh simulator (its own copy: compiling or changing its knobs leaves the others
        as they are): the trained one (``weights: trained``; random weights of ``model``
        without a run), or ``model`` with ``overrides`` and random weights."""
        if weights not in (TRAINED, RANDOM):
            raise BenchError(f"weights must be {TRAINED} or {RANDOM} (got {weights})")
        if weights == TRAINED and overrides:
            raise BenchError(
                f"weights: trained with overrides {dict(overrides)}: a trained model's "
                "architecture is its own; give the configuration weights: random"
            )
        if weights == TRAINED and self.trained is not None:
            return copy.deepcopy(self.trained)
        return make_simulator(self.model, overrides or {}, self.stats)

    def weights_label(self, weights: str) -> str:
        """What the rows of ``weights`` run: the run (trained, with one), else random weights."""
        return self.label if weights == TRAINED else "random weights"


def learned_source(cfg: DictConfig, stats: dict) -> Source:
    """The :class:`Source` of ``cfg.run`` (null: ``cfg.model`` with random weights)."""
    if cfg.get("run") is None:
        return Source(cfg.model, None, "random weights", stats)
    sim, run_cfg, _ = load_run(str(cfg.run))
    return Source(run_cfg.model, sim.eval(), str(cfg.run), stats)
