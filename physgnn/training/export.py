"""Shipping a trained run: a small run folder of weights only, loadable wherever a run is.

``python -m physgnn.ship RUN_DIR [OUT_DIR] [CHECKPOINT]`` (``physgnn ship``, ``make ship
RUN=...``; :func:`main`) writes ``OUT_DIR`` (default ``physgnn/pretrained``, what
``run=pretrained`` names) as a run folder holding only what the trained simulator needs:

- ``.hydra/config.yaml``: the run's own config (model, training recipe, dataset preset; its
  paths are interpolations, no machine's path);
- ``checkpoints/best-stepNNNNNN.ckpt``: the simulator's weights and normalisation buffers of
  the run's best checkpoint (or ``CHECKPOINT``), without the optimiser state (about a third of
  a training checkpoint);
- ``run.json``: status ``finished``, the run's experiment, overrides, seed, steps, training
  time, sessions and threads, the machine, the commit it was exported at, the source
  checkpoint, and ``weights_format`` (:data:`~physgnn.training.runs.WEIGHTS_FORMAT`), which
  :func:`~physgnn.training.runs.load_run` checks.
"""

from __future__ import annotations

import errno
import platform
import sys
from datetime import datetime
from pathlib import Path

import torch

from physgnn.errors import DISK_WORDS, PhysgnnError, one_line
from physgnn.files import (
    atomic_path,
    claimed_outputs,
    code_commit,
    portable,
    write_text,
)
from physgnn.training.checks import not_a_checkpoint
from physgnn.training.runs import (
    PRETRAINED_DIR,
    WEIGHTS_FORMAT,
    check_done,
    checkpoint_of,
    load_checkpoint,
    read_run_json,
    write_run_json,
)

KEPT = (
    "experiment",
    "overrides",
    "seed",
    "dataset",
    "epochs",
    "max_epochs",
    "global_step",
    "train_time_s",
    "sessions",
    "threads",
    "host",
    "pairs_seen",
)
# What a package holds (replaced whole by the next ship into its folder).
SHIPPED = ("checkpoints", ".hydra", "run.json")


def export_run(run_dir: Path, out_dir: Path = PRETRAINED_DIR, checkpoint: Path | None = None):
    """Write ``out_dir`` from ``run_dir`` (module doc), a finished or truncated run (one still
    training, interrupted or failed is refused in one line); returns the weights file. The
    package is written whole into a staging folder beside ``out_dir``, then moved in
    (:func:`~physgnn.files.staged_outputs`): on any failure (a full disk) the earlier package
    in ``out_dir`` is left as it was."""
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    if run_dir.resolve() == out_dir.resolve():
        raise PhysgnnError(
            f"RUN_DIR and OUT_DIR are the same folder ({portable(out_dir)}): name the run to "
            "export (make ship RUN=<a finished run folder>)"
        )
    if not run_dir.is_dir():
        raise PhysgnnError(
            f"RUN_DIR {run_dir} does not exist: give the folder of a finished run "
            "(outputs/runs/<experiment>/<time>)"
        )
    check_done(run_dir, "ship it")
    source = own_checkpoint(run_dir, Path(checkpoint)) if checkpoint else checkpoint_of(run_dir)
    full = load_checkpoint(
        source, "export {other} (CHECKPOINT=...), or train the run again", weights_only=True
    )
    weights = {k: v for k, v in full["state_dict"].items() if k.startswith("simulator.")}
    step = int(full.get("global_step", 0))
    name = Path("checkpoints") / f"best-step{step:06d}.ckpt"  # one set of weights per folder
    failed = None
    try:
        # ship takes no overwrite=true
        with claimed_outputs(out_dir, "OUT_DIR", SHIPPED, overwrite=None) as staging:
            _write_package(staging, run_dir, name, (full, weights, step, source))
    except (PhysgnnError, FileExistsError):
        raise
    except (OSError, RuntimeError) as err:  # torch's writer on a full disk: a RuntimeError
        failed = _reason(err)
    if failed is not None:  # raised here, not chained: the failed writer's open file is let go
        raise ShipError(
            f"OUT_DIR {portable(out_dir)}: the new package could not be written in its staging "
            f"folder beside it ({failed}); the earlier package there is as it was: free space "
            "there, or choose another OUT_DIR"
        )
    return out_dir / name


def own_checkpoint(run_dir: Path, checkpoint: Path) -> Path:
    """``checkpoint``, a file of ``run_dir/checkpoints`` (the package's run.json names the run
    it comes from: another run's weights would be shipped under this run's name), else one
    line naming CHECKPOINT and the fix."""
    folder = run_dir / "checkpoints"
    if not checkpoint.is_file():
        raise PhysgnnError(
            f"CHECKPOINT {checkpoint} does not exist: give one of RUN_DIR's checkpoints "
            f"({portable(folder)}/last.ckpt or best-*.ckpt), or leave it out (its best)"
        )
    if checkpoint.resolve().parent != folder.resolve():
        raise PhysgnnError(
            f"CHECKPOINT {checkpoint} is not one of RUN_DIR's checkpoints (in "
            f"{portable(folder)}): the package's run.json names RUN_DIR as the run its weights "
            "come from; give a checkpoint of that folder, or ship the checkpoint's own run "
            "(physgnn ship <its run folder> OUT_DIR CHECKPOINT)"
        )
    if not_a_checkpoint(checkpoint):
        raise PhysgnnError(
            f"CHECKPOINT {checkpoint} is not a checkpoint (torch.save writes a zip, this file is "
            "not one): give one of RUN_DIR's .ckpt files, or leave it out (its best)"
        )
    return checkpoint


class ShipError(PhysgnnError, OSError):
    """The package could not be written (one line naming the folder and the fix)."""


def _reason(err: BaseException) -> str:
    """Why a write failed, in a few words (a full disk named so, whoever wrapped it)."""
    text = str(err)
    wrapped = isinstance(err, RuntimeError) and "Read-only" not in text  # torch's, h5py's words
    if getattr(err, "errno", None) in (errno.ENOSPC, errno.EDQUOT) or (
        wrapped and any(w in text for w in DISK_WORDS)  # "... unexpected pos 4160 vs 4096"
    ):
        return "no space left on device"
    return one_line(err)[:200]


def _write_package(folder: Path, run_dir: Path, name: Path, loaded: tuple) -> None:
    """The package's files in ``folder``: the weights ``name``, the config and run.json."""
    full, weights, step, source = loaded
    (folder / name).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / name) as tmp:
        torch.save({"state_dict": weights, "global_step": step, "epoch": full.get("epoch")}, tmp)
    write_text(folder / ".hydra" / "config.yaml", (run_dir / ".hydra" / "config.yaml").read_text())
    info = {k: v for k, v in read_run_json(run_dir).items() if k in KEPT}
    info |= {
        "status": "finished",
        "weights_format": WEIGHTS_FORMAT,
        "checkpoint_step": step,
        "exported_from": f"{portable(run_dir)} ({source.name})",
        "commit": code_commit(),
        "machine": f"{platform.machine()} {platform.processor() or platform.system()}",
        "exported": datetime.now().isoformat(timespec="seconds"),
    }
    write_run_json(folder, info)


USAGE = "usage: physgnn ship RUN_DIR [OUT_DIR] [CHECKPOINT]   (python -m physgnn.ship; --help)"


def main(argv: list[str]) -> int:
    """``physgnn ship``'s work on its arguments (:mod:`physgnn.ship`): 0, or 2 after one line."""
    if not 1 <= len(argv) <= 3:
        print(USAGE)
        return 2
    out = Path(argv[1]) if len(argv) > 1 else PRETRAINED_DIR
    try:
        target = export_run(Path(argv[0]), out, Path(argv[2]) if len(argv) > 2 else None)
    except (OSError, PhysgnnError) as err:  # a missing run or checkpoint, a foreign folder
        print(f"error: {err}", file=sys.stderr)
        return 2
    size = target.stat().st_size / 1e6
    print(f"exported {argv[0]} to {portable(out)} ({target.name}, {size:.1f} MB)")
    return 0
