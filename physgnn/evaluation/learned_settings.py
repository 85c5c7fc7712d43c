"""Every trained run of ``make eval`` again at each of its own learned settings: the rows
``<run> · <setting>`` of metrics.csv (their column ``setting``), points of the same-work table
and Pareto figures beside the run as trained and pybullet at each substep count.

A setting (``learned_settings`` of conf/eval.yaml: name → knobs of
:data:`physgnn.models.settings.KNOBS`) is set on a fresh load of the run's weights
(:func:`physgnn.models.settings.with_knobs`: the run as trained is untouched), and rolls out
every test and OOD trajectory of the run's dataset from its first H+1 truth frames, as the
run itself does: the same start states, the same rollout settings and timing (batched scenes
or one at a time), under its own torch threads. Absent knobs: the run's own contact passes, no
constraint stage, the eval's ``compile`` and ``rollout.threads`` (null: the process's).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import torch
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError
from physgnn.evaluation.rollouts import Collected, roll_all, rollout_threads
from physgnn.evaluation.runs import RunInfo
from physgnn.models.settings import check_knobs, with_knobs
from physgnn.training import runs as training_runs

KEY = "learned_settings"


def check_settings(settings) -> dict[str, dict]:
    """The eval's ``learned_settings`` as ``{name: knobs}`` (each checked by
    :func:`~physgnn.models.settings.check_knobs`); null or ``{}``: none. Refused in one line
    naming the key: not a mapping, a knob unknown or out of range."""
    if settings is None:
        return {}
    if not isinstance(settings, Mapping):
        raise ConfigError(
            f"{KEY} must be null or a mapping of setting name to knobs, got {settings!r} "
            f"(e.g. {KEY}={{passes0: {{contact_passes: 0}}}})"
        )
    return {str(name): check_knobs(f"{KEY}.{name}", knobs) for name, knobs in settings.items()}


def setting_jobs(
    runs: list[RunInfo],
    settings: dict[str, dict],
    compile: bool = False,
    cache_dir=None,
    threads: int | None = None,
) -> list[RunInfo]:
    """Every trained run of ``runs`` (a run folder, not a constrained variant) at each setting
    of ``settings`` (:func:`check_settings`'s): named ``<run> · <setting>``, its experiment,
    overrides, seed and dataset the run's; ``extra``: ``setting`` (the name) and ``knobs``
    (every knob as it runs). ``compile``, ``cache_dir``: the eval's (the default of
    ``compile``); ``threads``: the default of the knob (the eval's ``rollout.threads``; None:
    the process's)."""
    trained = [r for r in runs if r.run_dir is not None and "constraints" not in r.extra]
    threads = threads or torch.get_num_threads()
    jobs = []
    for run in trained:
        for name, knobs in settings.items():
            sim, _, _ = training_runs.load_run(run.run_dir)
            sim, used = with_knobs(sim.eval(), knobs, threads, compile, cache_dir)
            jobs.append(
                dataclasses.replace(
                    run,
                    name=f"{run.name} · {name}",
                    simulator=sim,
                    extra={**run.extra, "setting": name, "knobs": used},
                )
            )
    return jobs


def setting_rows(
    jobs: list[RunInfo], data: dict, tol: float, settings: dict | None, batch_scenes: bool
) -> list[dict]:
    """Every job of :func:`setting_jobs` on every test and OOD trajectory of its dataset
    (``data``: ``{folder: {split: [Trajectory]}}``), rolled out as the learned runs are
    (``settings``: the rollout's keyword arguments; ``batch_scenes``) under its own torch
    threads: metrics.csv rows with ``setting`` set."""
    rows = []
    for job in jobs:
        out = Collected(keep=set(), film=[], tol=tol)
        roll_all([job], data, out, settings, batch_scenes, job.extra["knobs"]["threads"])
        rows += [row | {"setting": job.extra["setting"]} for row in out.rows]
    return rows


def eval_rows(
    cfg: DictConfig, runs: list[RunInfo], data: dict, settings: dict, batched: bool
) -> tuple[list[dict], list[RunInfo]]:
    """The rows of every trained run of ``runs`` at each of ``cfg.learned_settings``
    (:func:`setting_jobs`, :func:`setting_rows`) and those jobs; ``settings``: the rollout's
    keyword arguments, ``batched``: ``rollout.batch_scenes``; threads: ``rollout.threads``
    unless a setting names its own. None with ``learned_settings`` null or ``{}``."""
    chosen = check_settings(cfg.get(KEY))
    if not chosen:
        return [], []
    cache = OmegaConf.select(cfg, "paths.compile_cache")
    jobs = setting_jobs(runs, chosen, bool(cfg.get("compile")), cache, rollout_threads(cfg))
    return setting_rows(jobs, data, float(cfg.tol), settings, batched), jobs
