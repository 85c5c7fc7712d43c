"""Generation in shards, for a preset larger than one machine's patience (``paper``: about
2.8 CPU-hours): each shard simulates its share of the trajectories wherever a Hydra launcher
runs it (joblib processes here, SLURM jobs there), and the merge assembles exactly the files
one process writes.

- ``shard=i num_shards=n``: trajectory k of the preset's plan (every split, in file order) is
  shard k mod n's. Shard i writes its share of each split (``<split>.h5``, the dataset schema)
  and :data:`MANIFEST` (what made it: the config but ``data.dir``, the physgnn, schema and
  pybullet versions, its trajectories and their seeds) into ``<data.dir>.shards/shard-i-of-n``,
  built beside it and renamed when complete. A shard already there from the same config is
  kept (a sweep run again simulates only the missing ones); one from another config is
  replaced only with ``overwrite=true``.
- ``merge=true num_shards=n``: once every shard is there and was made with this config (else
  one line naming the shard and the fix), their trajectories go through the code a single run
  writes with, in the plan's order (:func:`physgnn.groundtruth.folders.build_folder`): the same
  trajectories (each seeded by its split and index alone), the same files, byte for byte. The
  shards are removed then.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from physgnn import __version__
from physgnn.data.dataset import (
    DATASET_MARKER,
    SCHEMA_VERSION,
    is_dataset,
    read_split,
    write_marker,
)
from physgnn.errors import ConfigError, PhysgnnError
from physgnn.groundtruth.engine import engine_version
from physgnn.groundtruth.folders import build_folder, clear, in_the_way
from physgnn.groundtruth.jobs import Job, progress_bar
from physgnn.locks import exclusive
from physgnn.physics.trajectory import Trajectory

MANIFEST = "shard.json"
SHARD_NAME = re.compile(r"shard-(\d+)-of-(\d+)")


class ShardError(PhysgnnError, RuntimeError):
    """A shard is missing or was made with another config (one line naming it and the fix)."""


def shards_root(out: Path) -> Path:
    """The folder of the shards of the dataset ``out``: ``<out>.shards`` beside it."""
    return out.with_name(out.name + ".shards")


def shard_dir(out: Path, i: int, n: int) -> Path:
    return shards_root(out) / f"shard-{i}-of-{n}"


def _whole(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def sharding(cfg: DictConfig) -> tuple[int | None, int | None, bool]:
    """``(shard, num_shards, merge)`` of the config, checked (one line naming the key)."""
    shard, n, merge = cfg.get("shard"), cfg.get("num_shards"), cfg.get("merge", False)
    if not isinstance(merge, bool):
        raise ConfigError(f"merge must be true or false, got {merge!r}")
    if n is None:
        if shard is not None:
            raise ConfigError(f"shard={shard} needs num_shards=N, the number of shards in all")
        if merge:
            raise ConfigError("merge=true needs num_shards=N, the number of shards to assemble")
        return None, None, False
    if not _whole(n) or n < 1:
        raise ConfigError(f"num_shards must be a whole number >= 1, got {n!r}")
    if cfg.get("export_scene"):
        raise ConfigError("export_scene writes scene files only: drop num_shards, shard, merge")
    if merge and shard is not None:
        raise ConfigError(f"merge=true assembles every shard: drop shard={shard}")
    if not merge and shard is None:
        raise ConfigError(
            f"num_shards={n} needs shard=i (0 to {n - 1}) to write one shard, or merge=true "
            "to assemble the dataset from them"
        )
    if shard is not None and (not _whole(shard) or not 0 <= shard < n):
        raise ConfigError(f"shard must be a whole number from 0 to {n - 1}, got {shard!r}")
    return shard, n, merge


def check_count(jobs: list[Job], n: int, preset: str) -> None:
    if n > len(jobs):
        raise ConfigError(
            f"num_shards={n} but data={preset} has {len(jobs)} trajectories: choose "
            f"num_shards <= {len(jobs)}"
        )


def manifest(cfg: DictConfig, jobs: list[Job], i: int, n: int) -> dict:
    """What shard ``i`` of ``n`` of the plan ``jobs`` is made from, as its JSON reads back."""
    data = OmegaConf.to_container(cfg.data, resolve=True)
    data.pop("dir", None)  # where the dataset goes may differ between machines
    engine = OmegaConf.to_container(cfg.get("engine") or {}, resolve=True)
    made = {
        "shard": i,
        "num_shards": n,
        "physgnn_version": __version__,
        "schema_version": SCHEMA_VERSION,
        "engine_version": engine_version(),
        "config": {"data": data, "engine": engine},
        "trajectories": [[j.split, j.group, j.seed] for j in jobs[i::n]],
    }
    return json.loads(json.dumps(made))


def read_manifest(folder: Path) -> dict | None:
    """A complete shard's :data:`MANIFEST`; None where there is none."""
    try:
        return json.loads((Path(folder) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None


def differences(there, here, key: str = "") -> list[str]:
    """``key: <there> there, <here> here`` for each value that differs (nested keys dotted;
    the ``config.`` prefix left out)."""
    if isinstance(there, dict) and isinstance(here, dict):
        out = []
        for k in sorted(set(there) | set(here)):
            name = k if key in ("", "config") else f"{key}.{k}"
            out += differences(there.get(k, "absent"), here.get(k, "absent"), name)
        return out
    if there == here:
        return []
    return [f"{key}: {_short(there)} there, {_short(here)} here"]


def _short(value) -> str:
    """``value`` as JSON, cut after 40 characters."""
    text = json.dumps(value)
    return text[:40] + ("..." if len(text) > 40 else "")


def write_shard(cfg: DictConfig, jobs: list[Job], i: int, n: int, source: Callable) -> Path:
    """Shard ``i`` of ``n`` of the plan ``jobs`` (trajectories from ``source``) into
    :func:`shard_dir`; kept when already there from this config."""
    out = Path(cfg.data.dir)
    folder, mine = shard_dir(out, i, n), manifest(cfg, jobs, i, n)
    _claim_root(shards_root(out), cfg.data.name)
    way_out = "wait for it to end, or choose another data.dir (paths.outputs)"
    with exclusive(folder.with_name(folder.name + ".lock"), f"shard {i} of {n}", way_out):
        if _kept(folder, mine, bool(cfg.overwrite)):
            print(f"shard {i} of {n}: kept, {folder} holds it from this config already")
            return folder
        return build_folder(
            folder, cfg.data.name, jobs[i::n], source, stats=False, notes={MANIFEST: mine}
        )


def _claim_root(root: Path, preset: str) -> None:
    """Make the shards' folder, marked as physgnn's; one with files physgnn did not write is
    refused. Shards started together make it at once: the one whose ``mkdir`` succeeds marks
    it, the others take it as it is (holding nothing but the marker and shards)."""
    try:
        root.mkdir(parents=True)
    except FileExistsError:
        if not root.is_dir():
            raise FileExistsError(
                f"{root} is a file: move it, or choose another data.dir"
            ) from None
        mine = (DATASET_MARKER, "shard-")
        foreign = [p.name for p in root.iterdir() if not p.name.startswith(mine)]
        if foreign and not is_dataset(root):
            raise FileExistsError(
                f"{root} holds files that physgnn did not write ({foreign[0]}): move them "
                "away, or choose another data.dir"
            ) from None
        return
    write_marker(root, preset)


def _kept(folder: Path, mine: dict, overwrite: bool) -> bool:
    """``folder`` holds this very shard already; another config's is refused (one line) but
    with ``overwrite``; anything else of physgnn's there is replaced."""
    there = read_manifest(folder)
    if there == mine:
        return True
    if there is None:
        in_the_way(folder)
        return False
    if not overwrite:
        raise ShardError(
            f"shard {mine['shard']} of {mine['num_shards']} in {folder} was made with another "
            f"config ({differences(there, mine)[0]}): pass overwrite=true to replace it"
        )
    return False


def check_shards(cfg: DictConfig, jobs: list[Job], n: int) -> None:
    """Every shard of ``n`` is there and was made with this config, else one line naming the
    first wrong or the missing ones and the fix."""
    out = Path(cfg.data.dir)
    missing = []
    for i in range(n):
        there = read_manifest(shard_dir(out, i, n))
        if there is None:
            missing.append(i)
            continue
        wrong = differences(there, manifest(cfg, jobs, i, n))
        if wrong:
            raise ShardError(
                f"shard {i} of {n} ({shard_dir(out, i, n)}) was made with another config "
                f"({wrong[0]}): merge with the config the shards were made with, or write it "
                f"again with this one (shard={i} num_shards={n} overwrite=true)"
            )
    if missing:
        raise ShardError(_missing_line(out, missing, n))


def shard_counts(root: Path) -> set[str]:
    """The ``num_shards`` of the shard folders in ``root`` (``shard-<i>-of-<n>``; a shard's
    lock file and a staging folder left by a killed shard are not shards)."""
    found = (SHARD_NAME.fullmatch(p.name) for p in root.glob("shard-*-of-*") if p.is_dir())
    return {m.group(2) for m in found if m is not None}


def _missing_line(out: Path, missing: list[int], n: int) -> str:
    root = shards_root(out)
    counts = sorted(shard_counts(root) - {str(n)})
    held = f"; {root} holds shards of num_shards={', '.join(counts)}" if counts else ""
    which = ", ".join(map(str, missing))
    return (
        f"shard {which} of {n} missing in {root} (not written yet, running, or failed): write "
        f"it with this command's overrides and shard=i in place of merge=true, then merge "
        f"again{held}"
    )


def shard_reader(out: Path, jobs: list[Job], n: int, progress: bool) -> Callable:
    """``read(split_jobs) -> trajectories`` of one split from the shards of ``out``, in the
    order of ``split_jobs`` (a merge's ``source``), each checked against its job's seed."""
    owner = {(j.split, j.group): k % n for k, j in enumerate(jobs)}

    def read(split_jobs: list[Job]) -> list[Trajectory]:
        split, found = split_jobs[0].split, {}
        shards = sorted({owner[j.split, j.group] for j in split_jobs})
        with progress_bar(progress, "merge") as bar:
            task = bar.add_task("", total=len(shards))
            for i in shards:
                path = shard_dir(out, i, n) / f"{split}.h5"
                found.update((t.name, _as_simulated(t)) for t in read_split(path))
                bar.update(task, advance=1, description=f"{split}: shard {i} of {n}")
        for j in split_jobs:
            if j.group not in found or found[j.group].attrs.get("seed") != j.seed:
                i = owner[j.split, j.group]
                raise ShardError(
                    f"{split}/{j.group} (seed {j.seed}) is not in {shard_dir(out, i, n)}: "
                    f"write that shard again (shard={i} num_shards={n} overwrite=true)"
                )
        return [found[j.group] for j in split_jobs]

    return read


def _as_simulated(traj: Trajectory) -> Trajectory:
    """A trajectory read back as the simulation gave it: without the ``physgnn_version`` the
    writer adds (the manifest's check made it this one's), which written again would leave the
    same contents at other bytes."""
    attrs = {k: v for k, v in traj.attrs.items() if k != "physgnn_version"}
    return dataclasses.replace(traj, attrs=attrs)


def remove_shards(out: Path, n: int) -> None:
    """The ``n`` shards of ``out`` gone once merged; their folder too when nothing else is
    left in it."""
    for i in range(n):
        clear(shard_dir(out, i, n))
    root = shards_root(out)
    if is_dataset(root) and all(p.name == DATASET_MARKER for p in root.iterdir()):
        shutil.rmtree(root)
