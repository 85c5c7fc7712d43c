"""``python -m physgnn.generate [data=small|tiny|paper] [overwrite=true] [workers=N]
[export_scene=FOLDER]``.

Writes ``train.h5, val.h5, test.h5, ood.h5, stats.json`` into ``cfg.data.dir``. Each
trajectory's seed is derived from the preset seed by ``numpy.random.SeedSequence(seed,
spawn_key=(split, index))``, so the data depend on the config and seed only, never on the
number of workers. Files are written into a staging folder that replaces the dataset only
when complete: an interrupted run leaves a previous dataset intact.
"""

from __future__ import annotations

import multiprocessing as mp
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn.data.dataset import compute_stats, write_split, write_stats
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.scenefile import write_scene
from physgnn.groundtruth.settings import EngineSettings
from physgnn.physics.scene import SceneError
from physgnn.physics.trajectory import Trajectory

SPLITS = ("train", "val", "test", "ood")
FILES = tuple(f"{s}.h5" for s in SPLITS) + ("stats.json",)


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
    fit = data.get("fit_scene")
    fit_scene = test_scene | (OmegaConf.to_container(fit, resolve=True) if fit else {})
    for split in ("train", "val", "test"):
        n = int(data.splits[split])
        if n < 1:
            raise SceneError(f"data.splits.{split} must be >= 1 (got {n})")
        scene = test_scene if split == "test" else fit_scene
        for i in range(n):
            jobs.append(
                Job(split, i, f"traj_{i:05d}", scene, engine, trajectory_seed(data.seed, split, i))
            )
    for i, (key, cfg) in enumerate((data.get("ood") or {}).items()):
        ood = OmegaConf.to_container(cfg, resolve=True)
        jobs.append(Job("ood", i, str(key), ood, engine, trajectory_seed(data.seed, "ood", i)))
    return jobs


def run_job(job: Job) -> Trajectory:
    """Build and simulate one scene; the trajectory carries its seed, scene and config."""
    scene = build_scene(job.scene, np.random.default_rng(job.seed))
    traj = simulate(scene, job.engine)
    traj.attrs.update(
        group=job.group,
        seed=job.seed,
        scene=job.scene["name"],
        scene_config=OmegaConf.to_yaml(OmegaConf.create(job.scene)),
    )
    return traj


def _progress(enabled: bool) -> Progress:
    return Progress(
        TextColumn("[bold]generate"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.description}"),
        disable=not enabled,
    )


def run_jobs(jobs: list[Job], workers: int, progress: bool = True) -> list[Trajectory]:
    """Simulate ``jobs`` on ``workers`` processes (one pybullet client each), in order."""
    results: list[Trajectory | None] = [None] * len(jobs)
    with _progress(progress) as bar:
        task = bar.add_task("", total=len(jobs))
        if workers <= 1:
            for k, job in enumerate(jobs):
                results[k] = run_job(job)
                bar.update(task, advance=1, description=f"{job.split}/{job.group}")
        else:
            with mp.get_context("fork").Pool(workers) as pool:
                it = pool.imap_unordered(_indexed, list(enumerate(jobs)))
                for k, traj in it:
                    results[k] = traj
                    bar.update(task, advance=1, description=f"{jobs[k].split}/{jobs[k].group}")
    return results  # type: ignore[return-value]


def _indexed(item: tuple[int, Job]) -> tuple[int, Trajectory]:
    return item[0], run_job(item[1])


def _check_target(out: Path, overwrite: bool) -> None:
    existing = [f for f in FILES if (out / f).exists()]
    if existing and not overwrite:
        raise FileExistsError(
            f"dataset {out} already exists ({', '.join(existing)}); "
            "pass overwrite=true to replace it"
        )


def _swap_in(staging: Path, out: Path) -> None:
    """Replace ``out`` by the complete ``staging`` folder (the old one is removed last)."""
    old = out.with_name(out.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if out.exists():
        out.rename(old)
    staging.rename(out)
    shutil.rmtree(old, ignore_errors=True)


def export_scenes(jobs: list[Job], folder: Path) -> Path:
    """Write each job's initial scene as a YAML scene file ``<split>_<group>.yaml``."""
    for job in jobs:
        scene = build_scene(job.scene, np.random.default_rng(job.seed))
        write_scene(folder / f"{job.split}_{job.group}.yaml", scene)
    return folder


def generate(cfg: DictConfig) -> Path:
    """Generate the dataset of ``cfg.data`` into ``cfg.data.dir``; returns that folder. With
    ``export_scene=FOLDER``: write the preset's scenes as scene files there instead."""
    data = cfg.data
    if cfg.get("export_scene"):
        engine = OmegaConf.to_container(cfg.get("engine") or {}, resolve=True)
        return export_scenes(plan(data, engine), Path(cfg.export_scene))
    out = Path(data.dir)
    _check_target(out, bool(cfg.overwrite))
    engine = OmegaConf.to_container(cfg.get("engine") or {}, resolve=True)
    EngineSettings.from_cfg(engine)  # fail early on a bad key
    jobs = plan(data, engine)
    staging = out.with_name(out.name + ".partial")
    shutil.rmtree(staging, ignore_errors=True)
    try:
        for split in SPLITS:  # one split in memory at a time
            trajs = run_jobs(
                [j for j in jobs if j.split == split],
                int(cfg.workers),
                bool(cfg.get("progress", True)),
            )
            write_split(staging / f"{split}.h5", trajs, {"split": split, "preset": data.name})
            if split == "train":
                write_stats(staging, compute_stats(trajs))
        _swap_in(staging, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out


def written(out: Path) -> str:
    """The line ``python -m physgnn.generate`` prints: a dataset (it has ``stats.json``) or
    the scene files of ``export_scene``."""
    kind = "dataset" if (Path(out) / "stats.json").exists() else "scene files"
    return f"{kind} written to {out}"
