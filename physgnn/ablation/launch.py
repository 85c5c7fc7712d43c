"""Run the study's jobs: ``local`` (``n_jobs`` worker processes on this machine, joblib) or
``slurm`` (one SLURM job each, submitit; ``launcher.slurm`` holds the executor parameters).
Either way the records come back to this process as each job ends, in the order they end, and
this process alone writes the registry."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from physgnn.ablation.jobs import StudyError
from physgnn.ablation.runner import lost_job, run_job


def launch(specs: list[dict], launcher: DictConfig, log_dir: Path) -> Iterator[dict]:
    """Yield the record of every spec as its job ends."""
    if not specs:
        return iter(())
    if launcher.name == "local":
        return _local(specs, int(launcher.n_jobs))
    if launcher.name == "slurm":
        return _slurm(specs, launcher, log_dir)
    raise StudyError(f"launcher.name must be local or slurm, got '{launcher.name}'")


def _local(specs: list[dict], n_jobs: int) -> Iterator[dict]:
    if n_jobs < 1:
        raise StudyError(f"launcher.n_jobs must be >= 1, got {n_jobs}")
    if n_jobs == 1:
        return (run_job(spec) for spec in specs)
    from joblib import Parallel, delayed

    parallel = Parallel(n_jobs=n_jobs, return_as="generator_unordered")
    return parallel(delayed(run_job)(spec) for spec in specs)


def _slurm(specs: list[dict], launcher: DictConfig, log_dir: Path) -> Iterator[dict]:
    import submitit

    executor = submitit.AutoExecutor(folder=str(log_dir / "%j"), cluster=launcher.get("cluster"))
    executor.update_parameters(**OmegaConf.to_container(launcher.slurm, resolve=True))
    pending = [(executor.submit(run_job, spec), spec) for spec in specs]
    while pending:
        for job, spec in [p for p in pending if p[0].done()]:
            pending.remove((job, spec))
            try:
                yield job.result()
            except Exception as err:  # the SLURM job itself died (time limit, node failure)
                yield lost_job(spec, err)
        if pending:
            time.sleep(float(launcher.get("poll_s", 10)))
