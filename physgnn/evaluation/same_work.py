"""pybullet on the same work as the learned runs: the rows ``pybullet-<k>`` of metrics.csv.

At each substep count ``k`` the engine starts from exactly the start a learned run has (its
first H+1 truth frames: the positions, orientations and velocities of frame H, the frames
before it copied from the truth as a rollout's are), runs at the truth's other settings
(``engine_settings`` of each trajectory) to the truth's last frame, and is scored with the
same metrics against the same truth (:func:`physgnn.evaluation.rollouts.metrics_row`).

Timing is the learned rollouts': one scene at a time in this process (``batch_scenes`` off:
each row its own frames per second), or every scene of a split at once in ``pybullet.processes``
processes (``batch_scenes`` on: every row the split's scene-frames per wall-clock second, as the
batched learned rollout's). By default as many processes as the learned rollouts have threads
(``rollout.threads``, 1), so that both sides of a same-work row use as many cores; the rows'
``threads`` column says how many. Both times include creating the bodies (a few ms per scene).
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing as mp
import os
import time

from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError, forked_worker
from physgnn.evaluation.rollouts import metrics_row, progress
from physgnn.evaluation.runs import SPLITS, RunInfo
from physgnn.groundtruth.engine import simulate
from physgnn.physics.trajectory import Trajectory, continued, scene_at
from physgnn.ranges import whole
from physgnn.report.table import ENGINE


def engine_of(truth: Trajectory, substeps: int) -> dict:
    """The truth's engine settings (its ``engine_settings`` attribute; the defaults when it
    has none) with ``substeps`` instead of its own."""
    stored = truth.attrs.get("engine_settings") or {}
    settings = json.loads(stored) if isinstance(stored, str) else dict(stored)
    return settings | {"substeps": int(substeps)}


def timed_run(job: tuple[Trajectory, int, int]) -> tuple[Trajectory, float]:
    """``job = (truth, H, substeps)``: the engine's run from frame H and its seconds."""
    truth, H, substeps = job
    t0 = time.perf_counter()
    run = simulate(scene_at(truth, H), engine_of(truth, substeps))
    return run, time.perf_counter() - t0


def engine_split(trajs: list[Trajectory], H: int, substeps: int, processes: int | None):
    """Every trajectory's engine run from frame ``H`` as a prediction with its ``fps``:
    ``processes`` None, one at a time here, each its own rate (the learned rollouts' one by
    one); a number, the split at once in that many processes, 1 here one after another, every
    row the split's scene-frames per wall-clock second (the batched learned rollout's rate on
    as many cores)."""
    jobs = [(t, H, substeps) for t in trajs]
    if processes in (None, 1):
        t0 = time.perf_counter()
        runs = [timed_run(job) for job in jobs]
        wall = time.perf_counter() - t0
    else:
        with mp.get_context("fork").Pool(processes, initializer=forked_worker) as pool:
            t0 = time.perf_counter()  # the workers' start is not timed
            runs = pool.map(timed_run, jobs, chunksize=1)
            wall = time.perf_counter() - t0
            pool.close()
            pool.join()  # the workers end on their own, not by the pool's SIGTERM
    if processes is None:
        return [
            continued(t, run, H, (run.n_frames - 1) / s)
            for t, (run, s) in zip(trajs, runs, strict=True)
        ]
    fps = sum(run.n_frames - 1 for run, _ in runs) / wall
    return [continued(t, run, H, fps) for t, (run, _) in zip(trajs, runs, strict=True)]


def engine_name(k: int, reference: RunInfo) -> str:
    """The rows' name of pybullet at ``k`` substeps for a reference of :func:`engine_jobs`:
    ``pybullet-<k><its suffix>``."""
    return f"{ENGINE}-{k}{reference.name}"


def seeded(trajs: list[Trajectory], H: int) -> list[Trajectory]:
    """The trajectories with a frame to predict after their ``H + 1`` seed frames."""
    return [t for t in trajs if t.n_frames > H + 1]


def engine_jobs(runs: list[RunInfo], several: bool) -> list[RunInfo]:
    """One reference per dataset and history H of the learned runs (``simulator`` None: the
    rows are made here, not rolled out); ``extra`` holds the dataset's H."""
    found = dict.fromkeys((r.dataset, int(r.simulator.H)) for r in runs if r.run_dir is not None)
    histories = {d: [h for dd, h in found if dd == d] for d, _ in found}
    jobs = []
    for dataset, H in found:
        suffix = f" (H={H})" if len(histories[dataset]) > 1 else ""
        suffix += f"[{dataset.name}]" if several else ""
        jobs.append(
            RunInfo(
                name=suffix,
                experiment=ENGINE,
                overrides=f"dataset={dataset}",
                dataset=dataset,
                extra={"H": H},
            )
        )
    return jobs


def check_settings(cfg: DictConfig | None) -> tuple[list[int], int] | None:
    """``(substeps, processes)`` of the eval's ``pybullet`` config (None: no rows); processes
    null means one per core."""
    if cfg is None:
        return None
    substeps = OmegaConf.to_container(cfg.substeps) if cfg.get("substeps") is not None else None
    if not substeps or not all(
        isinstance(k, int) and not isinstance(k, bool) and k >= 1 for k in substeps
    ):
        raise ConfigError(
            f"pybullet.substeps must be a list of whole numbers >= 1, got {substeps!r}"
        )
    processes = cfg.get("processes")
    if processes is None:
        processes = (
            len(os.sched_getaffinity(0))
            if hasattr(os, "sched_getaffinity")
            else os.cpu_count() or 1
        )
    processes = whole(1, also=(None,), what="one per core").check("pybullet.processes", processes)
    return [int(k) for k in substeps], processes


def engine_rows(
    jobs: list[RunInfo], data: dict, substeps: list[int], processes: int | None, tol: float
) -> list[dict]:
    """Every engine reference of :func:`engine_jobs` at every substep count on the test and
    OOD splits of its dataset: metrics.csv rows ``pybullet-<k><suffix>``, their ``substeps``
    and ``threads`` (the processes; 1 one at a time) columns set (``processes``:
    :func:`engine_split`'s; ``tol``: the penetration tolerance of the other rows)."""
    rows = []
    with progress() as bar:
        task = bar.add_task(ENGINE, total=len(jobs) * len(substeps) * len(SPLITS))
        for job, k in ((job, k) for job in jobs for k in substeps):
            H = job.extra["H"]
            info = dataclasses.replace(
                job, name=engine_name(k, job), overrides=f"substeps={k} H={H} {job.overrides}"
            )
            for split in SPLITS:
                bar.update(task, description=f"{info.name} · {split}")
                trajs = seeded(data[job.dataset][split], H)
                preds = engine_split(trajs, H, k, processes)
                for truth, pred in zip(trajs, preds, strict=True):
                    row = metrics_row(info, split, truth, pred, tol, threads=processes or 1)
                    rows.append(row | {"substeps": k})
                bar.advance(task)
    return rows
