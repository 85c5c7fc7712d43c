"""``python -m physgnn.generate [data=small|tiny|paper] [overwrite=true] [workers=N]
[export_scene=FOLDER] [shard=i num_shards=n | merge=true num_shards=n]``.

Writes ``train.h5, val.h5, test.h5, ood.h5, stats.json`` into ``cfg.data.dir``. Each
trajectory's seed is derived from the preset seed and its split and index alone
(:func:`physgnn.groundtruth.jobs.trajectory_seed`), so the data depend on the config and seed
only, never on the number of workers nor on shards. Files are written into a staging folder
``<dir>.partial`` that replaces the dataset only when complete: an interrupted run leaves a
previous dataset intact. Only folders carrying physgnn's dataset marker are ever replaced or
removed, and an existing dataset only with ``overwrite=true`` (:mod:`.folders`). Ctrl-C or
SIGTERM stop the workers quietly and end in one line. A preset too large for one machine runs
as shards, through a Hydra launcher, and a merge (:mod:`.shards`, :func:`after_sweep`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from physgnn.groundtruth.engine import as_stored
from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.folders import FILES, build_folder, check_target
from physgnn.groundtruth.jobs import SPLITS, Job, check_workers, plan, run_jobs, trajectory_seed
from physgnn.groundtruth.scenefile import write_scene
from physgnn.groundtruth.settings import EngineSettings
from physgnn.groundtruth.shards import (
    check_count,
    check_shards,
    read_manifest,
    remove_shards,
    shard_reader,
    sharding,
    shards_root,
    write_shard,
)
from physgnn.locks import exclusive
from physgnn.ranges import check_seed

__all__ = ["FILES", "SPLITS", "after_sweep", "generate", "plan", "trajectory_seed", "written"]


def export_scenes(jobs: list[Job], folder: Path) -> Path:
    """Write each job's initial scene, as its trajectory stores it, as a YAML scene file
    ``<split>_<group>.yaml`` (no file already there is replaced)."""
    paths = [folder / f"{job.split}_{job.group}.yaml" for job in jobs]
    taken = [p.name for p in paths if p.exists()]
    if taken:
        raise FileExistsError(
            f"export_scene: {folder} already holds {', '.join(taken[:3])}"
            f"{' ...' if len(taken) > 3 else ''}; choose another folder"
        )
    for job, path in zip(jobs, paths, strict=True):
        scene = build_scene(job.scene, np.random.default_rng(job.seed))
        write_scene(path, as_stored(scene, job.engine))
    return folder


def generate(cfg: DictConfig) -> Path:
    """Generate the dataset of ``cfg.data`` into ``cfg.data.dir``; returns that folder. With
    ``export_scene=FOLDER``: write the preset's scenes as scene files there instead; with
    ``shard=i num_shards=n``: shard i only (its folder is returned); with ``merge=true
    num_shards=n``: the dataset from the n shards."""
    data = cfg.data
    check_seed(data.get("seed"), "data.seed", f"conf/data/{data.name}.yaml: seed")
    shard, n, merge = sharding(cfg)
    if cfg.get("export_scene"):
        engine = OmegaConf.to_container(cfg.get("engine") or {}, resolve=True)
        return export_scenes(plan(data, engine), Path(cfg.export_scene))
    out = Path(data.dir)
    if shard is not None:
        check_target(out, bool(cfg.overwrite))  # the merge would refuse: say it now
        return _simulate(cfg, lambda jobs, source: write_shard(cfg, jobs, shard, n, source))
    way_out = "wait for it to end, or choose another data.dir (paths.outputs)"
    with exclusive(out.with_name(out.name + ".lock"), f"data.dir {out}", way_out):
        check_target(out, bool(cfg.overwrite))
        if merge:
            return _merge(cfg, out, n)
        return _simulate(cfg, lambda jobs, source: build_folder(out, data.name, jobs, source))


def _planned(cfg: DictConfig) -> list[Job]:
    engine = OmegaConf.to_container(cfg.get("engine") or {}, resolve=True)
    EngineSettings.from_cfg(engine)  # fail early on a bad key
    return plan(cfg.data, engine)


def _simulate(cfg: DictConfig, write) -> Path:
    """``write(jobs, source)``: the plan's jobs, ``source`` simulating a list of them."""
    workers = check_workers(cfg.workers)
    jobs = _planned(cfg)
    if cfg.get("num_shards") is not None:
        check_count(jobs, cfg.num_shards, cfg.data.name)
    progress = bool(cfg.get("progress", True))
    return write(jobs, lambda split_jobs: run_jobs(split_jobs, workers, progress))


def _merge(cfg: DictConfig, out: Path, n: int) -> Path:
    """The dataset from the ``n`` shards beside ``out``; the shards removed then."""
    jobs = _planned(cfg)
    check_count(jobs, n, cfg.data.name)
    check_shards(cfg, jobs, n)
    read = shard_reader(out, jobs, n, bool(cfg.get("progress", True)))
    build_folder(out, cfg.data.name, jobs, read)
    remove_shards(out, n)
    return out


def after_sweep(cfg: DictConfig, swept: dict[str, list]) -> str | None:
    """At the end of a sweep (``hydra.callbacks.merge_shards`` in conf/generate.yaml): a sweep
    that ran every shard merges them (a shard that failed is then one line naming it); one
    that ran some of them says how to merge once all are written. Other sweeps: nothing."""
    n, ran = cfg.get("num_shards"), swept.get("shard")
    if ran is None or not isinstance(n, int) or cfg.get("merge"):
        return None
    varied = [k for k, values in swept.items() if len(values) > 1 and k != "shard"]
    left = sorted(set(range(n)) - set(ran))
    if varied or left:
        why = f"shard {', '.join(map(str, left))} of {n} not in this sweep"
        if varied:
            why = f"the sweep varied {', '.join(varied)} too"
        return (
            f"shards written to {shards_root(Path(cfg.data.dir))}, not merged ({why}): once "
            f"every shard is written, the same overrides with merge=true num_shards={n} (no "
            "shard) assemble the dataset"
        )
    return written(generate(OmegaConf.merge(cfg, {"merge": True, "shard": None})))


def written(out: Path) -> str:
    """The line ``python -m physgnn.generate`` prints: a dataset (it has ``stats.json``), a
    shard, or the scene files of ``export_scene``."""
    shard = read_manifest(out)
    if shard is not None:
        return (
            f"shard {shard['shard']} of {shard['num_shards']} written to {out} (merge=true "
            "assembles the dataset once every shard is written)"
        )
    kind = "dataset" if (Path(out) / "stats.json").exists() else "scene files"
    return f"{kind} written to {out}"
