"""The trajectories of a preset (:func:`plan`) and their simulation (:func:`run_jobs`).

Each trajectory's seed is derived from the preset seed by ``numpy.random.SeedSequence(seed,
spawn_key=(split, index))``, so a trajectory depends on the config and seed only: never on the
number of worker processes, nor on the shard that simulates it
(:mod:`physgnn.groundtruth.shards`).
"""

from __future__ import annotations

import multiprocessing as mp
from dataclasses import dataclass

import numpy as np
from omegaconf import DictConfig, OmegaConf
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn.errors import forked_worker
from physgnn.groundtruth.engine import as_stored, simulate
from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.family_ranges import check_preset_scenes
from physgnn.physics.scene import SceneError
from physgnn.physics.trajectory import Trajectory
from physgnn.ranges import whole

SPLITS = ("train", "val", "test", "ood")


@dataclass(frozen=True)
class Job:
    """One trajectory to simulate (picklable: plain dicts only)."""

    split: str
    index: int
    group: str
    scene: dict
    engine: dict
    seed: int


def trajectory_seed(preset_seed: int, split: str, index: int) -> int:
    """A 32-bit seed for trajectory ``index`` of ``split``, independent of everything else."""
    ss = np.random.SeedSequence(int(preset_seed), spawn_key=(SPLITS.index(split), index))
    return int(ss.generate_state(1, np.uint32)[0])


def plan(data: DictConfig, engine: dict) -> list[Job]:
    """Every trajectory of a preset, in file order. ``data.fit_scene`` (optional) overrides keys
    of ``data.scene`` for the train and val splits only: the test split keeps the plain
    training family, so test figures stay comparable across training distributions."""
    jobs = []
    test_scene = OmegaConf.to_container(data.scene, resolve=True)
    fit = OmegaConf.to_container(data.fit_scene, resolve=True) if data.get("fit_scene") else {}
    fit_scene = test_scene | fit
    ood_scenes = OmegaConf.to_container(data.ood, resolve=True) if data.get("ood") else {}
    check_preset_scenes(test_scene, fit, ood_scenes)
    for split in ("train", "val", "test"):
        n = int(data.splits[split])
        if n < 1:
            raise SceneError(f"data.splits.{split} must be >= 1 (got {n})")
        scene = test_scene if split == "test" else fit_scene
        for i in range(n):
            jobs.append(
                Job(split, i, f"traj_{i:05d}", scene, engine, trajectory_seed(data.seed, split, i))
            )
    for i, (key, ood) in enumerate(ood_scenes.items()):
        jobs.append(Job("ood", i, str(key), ood, engine, trajectory_seed(data.seed, "ood", i)))
    return jobs


def run_job(job: Job) -> Trajectory:
    """Build and simulate one scene, from the start its trajectory stores
    (:func:`~physgnn.groundtruth.engine.as_stored`: the truth replays from its own frame 0);
    the trajectory carries its seed, scene and config."""
    scene = as_stored(build_scene(job.scene, np.random.default_rng(job.seed)), job.engine)
    traj = simulate(scene, job.engine)
    traj.attrs.update(
        group=job.group,
        seed=job.seed,
        scene=job.scene["name"],
        scene_config=OmegaConf.to_yaml(OmegaConf.create(job.scene)),
    )
    return traj


def progress_bar(enabled: bool, label: str = "generate") -> Progress:
    """The rich progress bar of generation (``label``: the work it counts)."""
    return Progress(
        TextColumn(f"[bold]{label}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.description}"),
        disable=not enabled,
    )


def run_jobs(jobs: list[Job], workers: int, progress: bool = True) -> list[Trajectory]:
    """Simulate ``jobs`` on ``workers`` processes (one pybullet client each), in order."""
    results: list[Trajectory | None] = [None] * len(jobs)
    with progress_bar(progress) as bar:
        task = bar.add_task("", total=len(jobs))
        if workers <= 1:
            for k, job in enumerate(jobs):
                results[k] = run_job(job)
                bar.update(task, advance=1, description=f"{job.split}/{job.group}")
        else:
            with mp.get_context("fork").Pool(workers, initializer=forked_worker) as pool:
                it = pool.imap_unordered(_indexed, list(enumerate(jobs)))
                for k, traj in it:
                    results[k] = traj
                    bar.update(task, advance=1, description=f"{jobs[k].split}/{jobs[k].group}")
    return results  # type: ignore[return-value]


def _indexed(item: tuple[int, Job]) -> tuple[int, Trajectory]:
    return item[0], run_job(item[1])


def check_workers(workers) -> int:
    return whole(1, what="processes").check("workers", workers)
