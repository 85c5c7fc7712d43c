"""``metrics.csv``: one row per rollout (run × split × trajectory), its columns, and the
groups the report averages over.

Rows are grouped by (experiment, configuration), the configuration being the run's Hydra
overrides without ``seed`` and ``+experiment``; every number is the mean ± std over all
rollouts of a group (trajectories × seeds). A diverged rollout's metrics are on its finite
prefix and its group is marked "diverged at step k".
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

from physgnn.files import read_rows, write_rows
from physgnn.metrics.names import TABLE
from physgnn.report.format import fmt_stat

# metrics.csv: identification columns, then the metrics (:data:`physgnn.metrics.names.TABLE`:
# the divergence step and the speed last; ``substeps``: pybullet's, on its rows
# ``pybullet-<k>``; ``setting``: the learned setting of a trained run at its own knobs, on its
# rows ``<run> · <setting>`` (physgnn.evaluation.learned_settings); each empty on the others;
# ``threads``: the torch threads a rollout ran on, empty on the ground truth's and pybullet's).
COLUMNS = [
    *("run", "experiment", "overrides", "seed", "split", "trajectory", "n_spheres", "n_frames"),
    *("substeps", "setting", "threads"),
    *TABLE,
]
INTS = ["n_spheres", "n_frames", "diverged_at", "seed", "substeps", "threads"]
FLOATS = [name for name in TABLE if name not in INTS]
REFERENCES = ("ground_truth", "static", "gravity_only")
# The experiment of pybullet's rows on the learned runs' own work (physgnn.evaluation.same_work)
ENGINE = "pybullet"
COMPONENTS = "ablation_components"
SPLITS = ("test", "ood")
SLEEP_SUFFIX = "+sleeping"
SLEEP_SCENE = "ood_resting_hit"
# drift_before_hit: radii a sphere resting in the truth moved before the truth moves it.
SLEEP_METRICS = (
    "drift_before_hit",
    "mse",
    "chamfer",
    "energy_gain",
    "depth_sphere",
    "pct_sphere",
    "fps",
)
# Overrides that do not name a configuration (train.yaml's override_dirname excludes most):
# these keys and everything under them (``trainer.devices=2``, ``+callbacks.rollout...``).
IGNORED_KEYS = (
    "seed",
    "experiment",
    "experiment_name",
    "ckpt_path",
    "run_dir",
    "trainer",
    "logger",
    "callbacks",
    "hydra",
    "hydra/launcher",
    "paths",
)


def write_csv(path: str | Path, rows: list[dict]) -> Path:
    """Write rows (dicts keyed by ``COLUMNS``; None → empty cell) atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path: str | Path) -> list[dict]:
    """Rows of a metrics.csv with numbers parsed (empty cell → None)."""
    return read_rows(path, FLOATS, INTS)


def config_label(overrides: str) -> str:
    """Overrides that change the model (no seed, experiment, hydra keys):
    ``"model.network.M=3"``."""
    keep = []
    for item in (overrides or "").split():
        key = item.split("=", 1)[0].lstrip("+~")
        if key in IGNORED_KEYS or key.startswith(tuple(f"{k}." for k in IGNORED_KEYS)):
            continue
        keep.append(item.lstrip("+"))
    return " ".join(keep) or "default"


def group_rows(rows: list[dict]) -> dict[tuple[str, str], list[dict]]:
    """Learned runs grouped by (experiment, configuration label); references, pybullet's rows,
    the learned settings' rows (the same-work view's alone) and the extra sleeping rollouts
    (see :func:`sleeping_section`) excluded."""
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for row in rows:
        if row["experiment"] in (*REFERENCES, ENGINE) or row["run"].endswith(SLEEP_SUFFIX):
            continue
        if row.get("setting"):
            continue
        groups[(row["experiment"] or "default", config_label(row["overrides"]))].append(row)
    return dict(sorted(groups.items()))


def select(rows: list[dict], split: str, scene: str | None = None) -> list[dict]:
    return [r for r in rows if r["split"] == split and (scene is None or r["trajectory"] == scene)]


def stat(rows: list[dict], metric: str) -> tuple[float, float, int] | None:
    """Mean, std (population) and count of the finite values of a metric, None if none."""
    vals = [r[metric] for r in rows if r[metric] is not None and math.isfinite(r[metric])]
    if not vals:
        return None
    mean = sum(vals) / len(vals)
    std = math.sqrt(sum((v - mean) ** 2 for v in vals) / len(vals))
    return mean, std, len(vals)


def frame_rate(rows: list[dict]) -> float | None:
    """Frames per second of ``rows`` together: their frames over their seconds (a row's seconds:
    ``n_frames / fps``; a row without ``n_frames`` weighs one frame), so that ``1 / rate`` is the
    mean cost of a frame; rows of one batch (one rate) give that rate. None if none is timed."""
    timed = [r for r in rows if r["fps"] is not None and math.isfinite(r["fps"]) and r["fps"] > 0]
    if not timed:
        return None
    frames = [r.get("n_frames") or 1 for r in timed]
    return sum(frames) / sum(n / r["fps"] for n, r in zip(frames, timed, strict=True))


def run_frame_rates(rows: list[dict]) -> tuple[float, float, int] | None:
    """Mean, std (population) and count over the runs of ``rows`` (their ``run``) of each
    run's :func:`frame_rate`: a configuration's frames/s and its spread over seeds, each seed's
    rate its frames over its seconds (the mean of its rows' rates overstates a run rolled out
    one scene at a time, whose small scenes run at many frames/s). None if none is timed."""
    by_run: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        by_run[row["run"]].append(row)
    rates = [{"rate": frame_rate(g)} for g in by_run.values()]
    return stat(rates, "rate")


def diverged_note(rows: list[dict]) -> str:
    """``"diverged at step k (m/n)"`` with k the earliest step, or "" when none diverged."""
    steps = [r["diverged_at"] for r in rows if r["diverged_at"] is not None]
    if not steps:
        return ""
    return f"diverged at step {min(steps)} ({len(steps)}/{len(rows)})"


def n_seeds(rows: list[dict]) -> int:
    return len({r["run"] for r in rows})


def cell(rows: list[dict], metric: str) -> str:
    """mean ± std, with the divergence mark when a rollout of these rows diverged."""
    text = fmt_stat(stat(rows, metric))
    steps = [r["diverged_at"] for r in rows if r["diverged_at"] is not None]
    return f"{text} ⚠ diverged at step {min(steps)}" if steps and text != "–" else text
