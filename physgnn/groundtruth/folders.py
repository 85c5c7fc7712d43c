"""The folders generation writes, and the rule that keeps a user's files safe: only folders
carrying physgnn's dataset marker (:data:`physgnn.data.dataset.DATASET_MARKER`) are ever
replaced or removed, and an existing dataset only with ``overwrite=true``; any other folder
in the way is an error. A folder is built in a staging folder (``<name>.partial``) and
swapped in only when complete, so an interrupted run leaves the previous one intact."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

from physgnn.data.dataset import DATASET_MARKER, is_dataset, write_marker, write_split
from physgnn.data.stats import compute_stats, write_stats
from physgnn.errors import Interrupted, interrupt_signal, signal_name
from physgnn.files import write_json
from physgnn.groundtruth.jobs import SPLITS, Job
from physgnn.physics.trajectory import Trajectory

FILES = tuple(f"{s}.h5" for s in SPLITS) + ("stats.json",)


def check_target(out: Path, overwrite: bool) -> None:
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


def in_the_way(path: Path) -> None:
    """A staging or old folder's place must be free or hold a leftover of physgnn's."""
    if path.exists() and not is_dataset(path):
        raise FileExistsError(f"{path} is in the way and physgnn did not write it: move it away")


def clear(path: Path) -> None:
    """Remove a leftover staging or old folder of an earlier run; anything else is an error."""
    in_the_way(path)
    if path.exists():
        shutil.rmtree(path)


def swap_in(staging: Path, out: Path) -> None:
    """Replace ``out`` (absent, empty or physgnn's: :func:`check_target`) by the complete
    ``staging`` folder; the old one is removed last."""
    old = out.with_name(out.name + ".old")
    clear(old)
    if is_dataset(out):
        out.rename(old)
    elif out.exists():
        out.rmdir()  # empty
    staging.rename(out)
    clear(old)


def build_folder(
    out: Path,
    preset: str,
    jobs: list[Job],
    source: Callable[[list[Job]], list[Trajectory]],
    stats: bool = True,
    notes: dict | None = None,
) -> Path:
    """Write ``<split>.h5`` of every split ``jobs`` hold (their trajectories: ``source(jobs
    of one split)``, one split in memory at a time), ``stats.json`` of the train split when
    ``stats``, and each JSON file of ``notes`` (name -> content) into a staging folder that
    replaces ``out`` (:func:`swap_in`) when complete; an interrupt leaves ``out`` as it was."""
    staging = out.with_name(out.name + ".partial")
    in_the_way(out.with_name(out.name + ".old"))
    clear(staging)
    write_marker(staging, preset)
    try:
        for split in SPLITS:
            split_jobs = [j for j in jobs if j.split == split]
            if not split_jobs:
                continue
            trajs = source(split_jobs)
            write_split(staging / f"{split}.h5", trajs, {"split": split, "preset": preset})
            if split == "train" and stats:
                write_stats(staging, compute_stats(trajs))
        for name, content in (notes or {}).items():
            write_json(staging / name, content)
        swap_in(staging, out)
    except KeyboardInterrupt as err:
        signum = interrupt_signal(err)
        raise Interrupted(
            f"generation stopped by {signal_name(signum)}: {out} was left as it was", signum
        ) from None
    finally:
        clear(staging)
    return out
