"""What training budget buys: checkpoints of one run, evaluated alike, against their step.

``python -m physgnn.report.learning_curve REPORT_DIR [OUT_DIR]`` (``make learning-curve``) reads
the ``metrics.csv`` and ``stability.csv`` of a ``make eval`` over runs whose names end in
``step<N>`` (a run's milestone checkpoints exported with ``make ship RUN=<run>
OUT=outputs/milestones/step<N> CHECKPOINT=<its step<N>.ckpt>``) and writes into ``OUT_DIR``
(default: the report folder) ``learning_curve.csv``, one row per step, and
``learning_curve.png``: test and OOD MSE, OOD max sphere–sphere depth (cubes, ramps), the
resting pile's drift, the tight pack's max depth and the free-fall error against the optimiser
step.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from physgnn.files import write_rows
from physgnn.report import freefall, stability, table
from physgnn.report.figures import plt, save_figure

COLUMNS = (
    "step",
    "run",
    "test_mse",
    "ood_mse",
    "cubes_depth",
    "ramps_depth",
    "ramps_tunnelled",
    "pile_drift",
    "tight_depth",
    "freefall_pct",
    "diverged",
)
PANELS = (
    ("test_mse", "test MSE (m²)"),
    ("ood_mse", "OOD MSE (m²)"),
    ("cubes_depth", "OOD cubes max depth (d)"),
    ("ramps_depth", "OOD ramps max depth (d)"),
    ("pile_drift", "resting pile drift (r)"),
    ("tight_depth", "tight pack max depth (d)"),
    ("freefall_pct", "free fall |error| (% of fall)"),
)
_STEP = re.compile(r"step0*(\d+)$")


def curve_rows(metrics: list[dict], hard: list[dict], fall: list[dict] = ()) -> list[dict]:
    """One row per run named ``...step<N>`` (:data:`COLUMNS`), sorted by step; a value a run
    lacks is None. Test and OOD MSE are means over the split's trajectories, None when one of
    them diverged (never a prefix average); ``diverged`` names the rollouts that did
    (``split/trajectory@frame`` of ``metrics.csv``, hard scenes of ``stability.csv``); the
    free-fall error is the mean |error| over the heights of ``freefall.csv``."""
    rows = []
    for run in sorted({r["run"] for r in metrics} | {r["run"] for r in hard}):
        found = _STEP.search(run)
        if not found:
            continue
        ours = [r for r in metrics if r["run"] == run]
        scenes = {r["scene"]: r for r in hard if r["run"] == run}
        gone = [
            f"{r['split']}/{r['trajectory']}@{r['diverged_at']}"
            for r in ours
            if r["diverged_at"] is not None
        ]
        gone += [
            f"{r['scene']}@{r['diverged_at']}"
            for r in scenes.values()
            if r["diverged_at"] is not None and r["source"] == "hard"
        ]
        rows.append(
            {
                "step": int(found.group(1)),
                "run": run,
                "test_mse": _split_mse(ours, lambda split: split == "test"),
                "ood_mse": _split_mse(ours, lambda split: split.startswith("ood")),
                "cubes_depth": _value(scenes, "ood_cubes", "max_pen_sphere"),
                "ramps_depth": _value(scenes, "ood_cubes_ramps", "max_pen_sphere"),
                "ramps_tunnelled": _value(scenes, "ood_cubes_ramps", "tunnelled"),
                "pile_drift": _value(scenes, "resting_pile", "rest_drift"),
                "tight_depth": _value(scenes, "tight_pack", "max_pen_sphere"),
                "freefall_pct": _mean(abs(r["z_error_pct"]) for r in fall if r["run"] == run),
                "diverged": " ".join(gone),
            }
        )
    return sorted(rows, key=lambda r: r["step"])


def _split_mse(rows: list[dict], in_split) -> float | None:
    mine = [r for r in rows if in_split(r["split"])]
    return (
        None if any(r["diverged_at"] is not None for r in mine) else _mean(r["mse"] for r in mine)
    )


def _mean(values):
    values = list(values)
    return sum(values) / len(values) if values else None


def _value(scenes: dict, scene: str, key: str):
    return scenes[scene][key] if scene in scenes else None


def plot_curve(rows: list[dict], path: str | Path) -> Path:
    """The :data:`PANELS` against the step, one point per checkpoint; a checkpoint with a
    diverged rollout is marked by a red dotted line in every panel."""
    fig, axes = plt.subplots(2, 4, figsize=(12.8, 6))
    for ax in axes.flat[len(PANELS) :]:
        ax.axis("off")
    for ax, (key, label) in zip(axes.flat, PANELS, strict=False):
        points = [(r["step"], r[key]) for r in rows if r[key] is not None]
        if points:
            ax.plot(*zip(*points, strict=True), "o-")
        for row in rows:
            if row["diverged"]:
                ax.axvline(row["step"], color="red", ls=":", lw=1)
        ax.set_xlabel("optimiser step")
        ax.set_title(label, fontsize=9)
        ax.set_ylim(bottom=0)
    if any(r["diverged"] for r in rows):
        fig.suptitle(
            "red dotted: a checkpoint with a diverged rollout (no MSE of that split)",
            fontsize=9,
            color="red",
        )
    return save_figure(fig, path)


def main(argv: list[str]) -> int:
    if not 1 <= len(argv) <= 2:
        print("usage: python -m physgnn.report.learning_curve REPORT_DIR [OUT_DIR]")
        return 2
    report = Path(argv[0])
    out = Path(argv[1]) if len(argv) > 1 else report
    try:
        metrics = table.read_csv(report / "metrics.csv")
        hard = stability.read_csv(report / "stability.csv")
        fall = (
            freefall.read_csv(report / "freefall.csv") if (report / "freefall.csv").exists() else []
        )
    except FileNotFoundError as err:
        print(f"error: {err.filename} not found: run make eval over the checkpoints first")
        return 2
    rows = curve_rows(metrics, hard, fall)
    if not rows:
        print(f"error: no run of {report / 'metrics.csv'} is named ...step<N>")
        return 2
    write_rows(out / "learning_curve.csv", rows, list(COLUMNS))
    print(f"wrote {plot_curve(rows, out / 'learning_curve.png')} ({len(rows)} checkpoints)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
