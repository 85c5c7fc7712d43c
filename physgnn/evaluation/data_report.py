"""``python -m physgnn.data_report [preset=small | dataset=PATH]``: Table 1 of a dataset.

The report's Table 1 measures the physics of the ground truth itself: normalised cumulative
energy gain and penetration (depth and percentage of spheres; sphere–sphere, sphere–ground,
sphere–other surfaces), mean ± std over the trajectories of the test and OOD splits (std with
ddof = 0). The energy uses the engine's velocities (the physics of the data); the gain with
finite-difference velocities (what a rollout records, so what a perfect model would show, and
what the ``ground_truth`` rows of ``make eval`` measure) is printed below the table. Prints the
table beside the report's Blender figures and writes ``<dataset>/report.json``:
``{"test": {"energy_gain": {"mean": .., "std": ..}, "depth_sphere": {..}, …}, "ood": {..}}``;
a report.json of the user's (in a folder without ``physgnn-dataset.json``) is never replaced.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, ListConfig
from rich.console import Console
from rich.table import Table

from physgnn.data.dataset import (
    DATASET_MARKER,
    SPLIT_FILES,
    generate_hint,
    presets,
    read_split,
)
from physgnn.errors import PhysgnnError
from physgnn.files import write_json
from physgnn.metrics import PENETRATION_KEYS, MetricError, trajectory_metrics
from physgnn.physics.trajectory import Trajectory
from physgnn.ranges import one_of
from physgnn.report.sections import BLENDER_TABLE1
from physgnn.report.table import SPLITS

KEYS = ("energy_gain", *PENETRATION_KEYS)
LABELS = {
    "energy_gain": "Normalised cumulative energy gain",
    "depth_sphere": "Normalised mean depth (sphere)",
    "depth_ground": "Normalised mean depth (ground)",
    "depth_static": "Normalised mean depth (static)",
    "pct_sphere": "% spheres intersecting (sphere-sphere)",
    "pct_ground": "% spheres intersecting (sphere-ground)",
    "pct_static": "% spheres intersecting (sphere-static)",
}


class DataReportError(PhysgnnError, ValueError):
    """The dataset cannot be reported (one line naming the problem)."""


def split_summary(trajectories: list, tol: float = 0.0, velocities: str = "engine") -> dict:
    """``{metric: {"mean": float, "std": float}}`` over the trajectories of one split
    (energy from the engine's or the finite-difference ``velocities``)."""
    if not trajectories:
        raise DataReportError("split has no trajectory")
    rows = [trajectory_metrics(_velocities(t, velocities), tol=tol) for t in trajectories]
    values = {k: np.array([row[k] for row in rows], dtype=np.float64) for k in KEYS}
    return {k: {"mean": float(v.mean()), "std": float(v.std())} for k, v in values.items()}


def _velocities(traj: Trajectory, velocities: str) -> Trajectory:
    """``traj`` with the engine's velocities or, ``"finite"``, finite-difference ones."""
    if velocities == "engine":
        return traj
    if velocities == "finite":
        return traj.with_finite_velocities()
    raise MetricError(f"velocities must be 'engine' or 'finite', got {velocities!r}")


def fmt(mean: float, std: float) -> str:
    """``mean ± std`` with 3 significant digits (scientific for small or large numbers)."""
    if mean != 0 and not 1e-2 <= abs(mean) < 1e3:
        return f"{mean:.2e} ± {std:.2e}"
    return f"{mean:.3g} ± {std:.3g}"


def table(summary: dict) -> Table:
    """Rich table: metric, ours per split, the report's per split."""
    splits = list(summary)
    t = Table(title="Table 1: physics of the ground truth (mean ± std over trajectories)")
    t.add_column("metric")
    for split in splits:
        t.add_column(f"ours {split}", justify="right")
    for split in splits:
        t.add_column(f"report (Blender) {split}", justify="right")
    for key in KEYS:
        ours = [fmt(**summary[s][key]) for s in splits]
        theirs = [
            fmt(*BLENDER_TABLE1[key][SPLITS.index(s)]) if s in SPLITS else "—" for s in splits
        ]
        t.add_row(LABELS[key], *ours, *theirs)
    return t


def data_report(cfg: DictConfig) -> dict:
    """Compute, print and write ``report.json`` for ``cfg.dataset``; returns its content."""
    folder = Path(cfg.dataset)
    splits = checked_splits(cfg.splits)
    if not folder.is_dir():
        raise DataReportError(missing_folder(cfg, folder))
    check_report_json(folder)
    summary, finite = {}, {}
    for split in splits:
        trajectories = read_split(folder / f"{split}.h5")
        try:
            summary[split] = split_summary(trajectories, float(cfg.tol))
        except DataReportError as e:
            raise DataReportError(f"{folder / f'{split}.h5'}: {e}") from None
        finite[split] = split_summary(trajectories, float(cfg.tol), "finite")["energy_gain"]
    console = Console()
    console = console if console.is_terminal else Console(width=160)  # files and pipes
    console.print(table(summary))
    gains = ", ".join(f"{s} {fmt(**v)}" for s, v in finite.items())
    console.print(
        f"Energy from the engine's velocities. With finite-difference velocities, as make "
        f"eval measures every row (a perfect rollout's gain): {gains}."
    )
    out = write_json(folder / "report.json", summary)
    print(f"wrote {out}")
    return summary


def checked_splits(splits) -> list[str]:
    """``splits``, a list of split names of a dataset (:data:`SPLIT_FILES`), else one line."""
    if not isinstance(splits, ListConfig | list) or not splits:
        raise DataReportError(
            f"splits must be a list of split names ({', '.join(SPLIT_FILES)}), got {splits!r} "
            f"(e.g. splits=[{splits if splits in SPLIT_FILES else 'test'}])"
        )
    name = one_of(*SPLIT_FILES, what="a dataset's split files")
    fix = "e.g. splits=[test,ood]"
    return [name.check(f"splits[{i}]", s, fix, DataReportError) for i, s in enumerate(splits)]


def missing_folder(cfg: DictConfig, folder: Path) -> str:
    """What to say of a dataset folder that is not there: ``preset=`` naming no preset of
    conf/data (its options), else how to generate it."""
    preset, options = str(cfg.get("preset")), presets()
    if folder == Path(cfg.paths.data_dir) / preset and preset not in options:
        return f"preset={preset}: no {preset!r} in conf/data (options: {', '.join(options)})"
    return f"dataset folder {folder} not found: {generate_hint(folder)}"


def check_report_json(folder: Path) -> None:
    """``folder/report.json`` may be written: absent, in a dataset physgnn wrote (its
    :data:`DATASET_MARKER`), or an earlier report of this command; else one line."""
    path = folder / "report.json"
    if not path.exists() or (folder / DATASET_MARKER).is_file() or _a_report(path):
        return
    raise DataReportError(
        f"dataset={folder} holds a report.json that physgnn did not write (no "
        f"{DATASET_MARKER} there): move it away, or report a copy of the split files in "
        "another folder"
    )


def _a_report(path: Path) -> bool:
    """``path`` holds a report.json this command wrote (a Table 1 summary per split)."""
    try:
        report = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(report, dict) and all(
        isinstance(v, dict) and "energy_gain" in v for v in report.values()
    )
