"""Run the study's jobs: ``local`` (``n_jobs`` job processes at a time on this machine) or
``slurm`` (one SLURM job each, submitit; ``launcher.slurm`` holds the executor parameters).
Either way the records come back to this process as each job ends, in the order they end, and
this process alone writes the registry."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import submitit
from omegaconf import DictConfig, OmegaConf

from physgnn.ablation.jobs import StudyError
from physgnn.ablation.runner import lost_job, run_job
from physgnn.ranges import one_of, whole

# What runs the jobs, and how many at a time on this machine (checked before any job is listed)
LAUNCHERS = one_of("local", "slurm", what="this machine, or one SLURM job per run")
N_JOBS = whole(1, what="jobs at a time on this machine", example=2)


def check_launcher(launcher: DictConfig) -> None:
    """``launcher.name`` is one of :data:`LAUNCHERS` and, for ``local``, ``launcher.n_jobs`` a
    whole number >= 1, else one line (:class:`StudyError`)."""
    LAUNCHERS.check("launcher.name", launcher.get("name"), error=StudyError)
    if launcher.name == "local":
        N_JOBS.check("launcher.n_jobs", launcher.get("n_jobs"), error=StudyError)


def launch(specs: list[dict], launcher: DictConfig, log_dir: Path) -> Iterator[dict]:
    """Yield the record of every spec as its job ends."""
    check_launcher(launcher)
    if not specs:
        return iter(())
    if launcher.name == "local":
        return _local(specs, int(launcher.n_jobs))
    return _slurm(specs, launcher, log_dir)


def _local(specs: list[dict], n_jobs: int) -> Iterator[dict]:
    """At most ``n_jobs`` job processes (``python -m physgnn.ablation.runner``) at a time, each
    in its own process group; on Ctrl-C or SIGTERM every running job gets SIGINT (its training
    saves ``last.ckpt`` and resumes at the next ``make study``) and is waited for."""
    queue, running = list(specs), []
    try:
        while queue or running:
            while queue and len(running) < n_jobs:
                running.append(_start(queue.pop(0)))
            for job in [j for j in running if j[0].poll() is not None]:
                running.remove(job)
                yield _result(*job)
            time.sleep(0.2)
    except BaseException:
        for proc, _, _ in running:
            os.killpg(proc.pid, signal.SIGINT)
        for proc, _, _ in running:
            try:
                proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
        raise


def _start(spec: dict) -> tuple[subprocess.Popen, dict, Path]:
    run_dir = Path(spec["run_dir"])
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    spec_path = run_dir.with_name(f"{run_dir.name}.job.json")
    spec_path.write_text(json.dumps(spec))
    out = run_dir.with_name(f"{run_dir.name}.record.json")
    out.unlink(missing_ok=True)
    cmd = [sys.executable, "-m", "physgnn.ablation.runner", str(spec_path), str(out)]
    return subprocess.Popen(cmd, start_new_session=True), spec, out


def _result(proc: subprocess.Popen, spec: dict, out: Path) -> dict:
    if out.exists():
        return json.loads(out.read_text())
    return lost_job(spec, RuntimeError(f"job process exited with code {proc.returncode}"))


def _slurm(specs: list[dict], launcher: DictConfig, log_dir: Path) -> Iterator[dict]:
    executor = submitit.AutoExecutor(folder=str(log_dir / "%j"), cluster=launcher.get("cluster"))
    params = OmegaConf.to_container(launcher.slurm, resolve=True)
    executor.update_parameters(**{k: v for k, v in params.items() if v is not None})
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
