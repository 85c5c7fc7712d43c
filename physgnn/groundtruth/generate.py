"""``python -m physgnn.generate [data=small|tiny|paper] [overwrite=true] [workers=N]
[export_scene=FOLDER]``.

Writes ``train.h5, val.h5, test.h5, ood.h5, stats.json`` into ``cfg.data.dir``. Each
trajectory's seed is derived from the preset seed by ``numpy.random.SeedSequence(seed,
spawn_key=(split, index))``, so the data depend on the config and seed only, never on the
number of workers. Files are written into a staging folder ``<dir>.partial`` that replaces the
dataset only when complete: an interrupted run leaves a previous dataset intact. Only folders
carrying physgnn's dataset marker (:data:`physgnn.data.dataset.DATASET_MARKER`) are ever
replaced or removed, and an existing dataset only with ``overwrite=true``: any other folder in
the way is an error. Ctrl-C or SIGTERM stop the workers quietly and end in one line.
"""

from __future__ import annotations

import multiprocessing as mp
import shutil
import signal
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn.data.dataset import (
    DATASET_MARKER,
    compute_stats,
    is_dataset,
    write_marker,
    write_split,
    write_stats,
)
from physgnn.errors import ConfigError, Interrupted, check_seed, interrupt_signal, signal_name
from physgnn.files import exclusive
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
            with mp.get_context("fork").Pool(workers, initializer=_quiet_worker) as pool:
                it = pool.imap_unordered(_indexed, list(enumerate(jobs)))
                for k, traj in it:
                    results[k] = traj
                    bar.update(task, advance=1, description=f"{jobs[k].split}/{jobs[k].group}")
    return results  # type: ignore[return-value]


def _indexed(item: tuple[int, Job]) -> tuple[int, Trajectory]:
    return item[0], run_job(item[1])


def _quiet_worker() -> None:
    """Pool workers leave Ctrl-C to the main process (no traceback per worker) and die on
    the pool's SIGTERM."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def check_workers(workers) -> int:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers must be a whole number >= 1 (processes), got {workers!r}")
    return workers


def _check_target(out: Path, overwrite: bool) -> None:
    """``out`` may be written: absent, an empty folder, or physgnn's dataset and overwrite."""
    if not out.exists():
        return
    if not out.is_dir():
        raise FileExistsError(f"data.dir {out} is a file: choose another data.dir")
    if not is_dataset(out):
        if any(out.iterdir()):
            raise FileExistsError(
                f"data.dir {out} is a folder with files that physgnn did not write (no "
                f"{DATASET_MARKER}); it is never replaced: choose another data.dir"
            )
        return
    if not overwrite:
        existing = [f for f in FILES if (out / f).exists()] or [DATASET_MARKER]
        raise FileExistsError(
            f"dataset {out} already exists ({', '.join(existing)}); "
            "pass overwrite=true to replace it"
        )


def _in_the_way(path: Path) -> None:
    """A staging or old folder's place must be free or hold a leftover of physgnn's."""
    if path.exists() and not is_dataset(path):
        raise FileExistsError(f"{path} is in the way and physgnn did not write it: move it away")


def _clear(path: Path) -> None:
    """Remove a leftover staging or old folder of an earlier run; anything else is an error."""
    _in_the_way(path)
    if path.exists():
        shutil.rmtree(path)


def _swap_in(staging: Path, out: Path) -> None:
    """Replace ``out`` (absent, empty or physgnn's: :func:`_check_target`) by the complete
    ``staging`` folder; the old dataset is removed last."""
    old = out.with_name(out.name + ".old")
    _clear(old)
    if is_dataset(out):
        out.rename(old)
    elif out.exists():
        out.rmdir()  # empty
    staging.rename(out)
    _clear(old)


def export_scenes(jobs: list[Job], folder: Path) -> Path:
    """Write each job's initial scene as a YAML scene file ``<split>_<group>.yaml`` (no file
    already there is replaced)."""
    paths = [folder / f"{job.split}_{job.group}.yaml" for job in jobs]
    taken = [p.name for p in paths if p.exists()]
    if taken:
        raise FileExistsError(
            f"export_scene: {folder} already holds {', '.join(taken[:3])}"
            f"{' ...' if len(taken) > 3 else ''}; choose another folder"
        )
    for job, path in zip(jobs, paths, strict=True):
        write_scene(path, build_scene(job.scene, np.random.default_rng(job.seed)))
    return folder


def generate(cfg: DictConfig) -> Path:
    """Generate the dataset of ``cfg.data`` into ``cfg.data.dir``; returns that folder. With
    ``export_scene=FOLDER``: write the preset's scenes as scene files there instead."""
    data = cfg.data
    check_seed(data.get("seed"), "data.seed", f"conf/data/{data.name}.yaml: seed")
    if cfg.get("export_scene"):
        engine = OmegaConf.to_container(cfg.get("engine") or {}, resolve=True)
        return export_scenes(plan(data, engine), Path(cfg.export_scene))
    out = Path(data.dir)
    way_out = "wait for it to end, or choose another data.dir (paths.outputs)"
    with exclusive(out.with_name(out.name + ".lock"), f"data.dir {out}", way_out):
        return _generate_into(out, cfg)


def _generate_into(out: Path, cfg: DictConfig) -> Path:
    """:func:`generate`'s work once it holds the dataset's lock."""
    data = cfg.data
    _check_target(out, bool(cfg.overwrite))
    workers = check_workers(cfg.workers)
    engine = OmegaConf.to_container(cfg.get("engine") or {}, resolve=True)
    EngineSettings.from_cfg(engine)  # fail early on a bad key
    jobs = plan(data, engine)
    staging = out.with_name(out.name + ".partial")
    _in_the_way(out.with_name(out.name + ".old"))
    _clear(staging)
    write_marker(staging, data.name)
    try:
        for split in SPLITS:  # one split in memory at a time
            trajs = run_jobs(
                [j for j in jobs if j.split == split], workers, bool(cfg.get("progress", True))
            )
            write_split(staging / f"{split}.h5", trajs, {"split": split, "preset": data.name})
            if split == "train":
                write_stats(staging, compute_stats(trajs))
        _swap_in(staging, out)
    except KeyboardInterrupt as err:
        signum = interrupt_signal(err)
        raise Interrupted(
            f"generation stopped by {signal_name(signum)}: {out} was left as it was", signum
        ) from None
    finally:
        _clear(staging)
    return out


def written(out: Path) -> str:
    """The line ``python -m physgnn.generate`` prints: a dataset (it has ``stats.json``) or
    the scene files of ``export_scene``."""
    kind = "dataset" if (Path(out) / "stats.json").exists() else "scene files"
    return f"{kind} written to {out}"
