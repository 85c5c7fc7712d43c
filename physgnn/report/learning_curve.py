"""What training budget buys: checkpoints of one run, evaluated alike, against their step.

``python -m physgnn.report.learning_curve REPORT_DIR [OUT_DIR]`` (``make learning-curve``) reads
the ``metrics.csv`` and ``stability.csv`` of a ``make eval`` over runs whose names end in
``step<N>`` (a run's milestone checkpoints exported with ``make ship RUN=<run>
OUT=outputs/milestones/step<N> CHECKPOINT=<its step<N>.ckpt>``) and writes into ``OUT_DIR``
(default: the report folder) ``learning_curve.csv``, one row per step, and
``learning_curve.png``: test MSE, OOD max sphere–sphere depth (cubes, ramps), the resting
pile's drift and the tight pack's max depth against the optimiser step.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from physgnn.files import write_rows
from physgnn.report import stability, table
from physgnn.report.figures import plt, save_figure

COLUMNS = ("step", "run", "test_mse", "cubes_depth", "ramps_depth", "ramps_tunnelled",
           "pile_drift", "tight_depth")  # fmt: skip
PANELS = (("test_mse", "test MSE (m²)"), ("cubes_depth", "OOD cubes max depth (d)"),
          ("ramps_depth", "OOD ramps max depth (d)"), ("pile_drift", "resting pile drift (r)"),
          ("tight_depth", "tight pack max depth (d)"))  # fmt: skip
_STEP = re.compile(r"step0*(\d+)$")


def curve_rows(metrics: list[dict], hard: list[dict]) -> list[dict]:
    """One row per run named ``...step<N>`` (:data:`COLUMNS`), sorted by step; a value a run
    lacks is None."""
    rows = []
    for run in sorted({r["run"] for r in metrics} | {r["run"] for r in hard}):
        found = _STEP.search(run)
        if not found:
            continue
        test = [r["mse"] for r in metrics if r["run"] == run and r["split"] == "test"]
        scenes = {r["scene"]: r for r in hard if r["run"] == run}
        rows.append({
            "step": int(found.group(1)), "run": run,
            "test_mse": sum(test) / len(test) if test else None,
            "cubes_depth": _value(scenes, "ood_cubes", "max_pen_sphere"),
            "ramps_depth": _value(scenes, "ood_cubes_ramps", "max_pen_sphere"),
            "ramps_tunnelled": _value(scenes, "ood_cubes_ramps", "tunnelled"),
            "pile_drift": _value(scenes, "resting_pile", "rest_drift"),
            "tight_depth": _value(scenes, "tight_pack", "max_pen_sphere"),
        })  # fmt: skip
    return sorted(rows, key=lambda r: r["step"])


def _value(scenes: dict, scene: str, key: str):
    return scenes[scene][key] if scene in scenes else None


def plot_curve(rows: list[dict], path: str | Path) -> Path:
    """The :data:`PANELS` against the step, one point per checkpoint."""
    fig, axes = plt.subplots(1, len(PANELS), figsize=(3.2 * len(PANELS), 3))
    for ax, (key, label) in zip(axes, PANELS, strict=True):
        points = [(r["step"], r[key]) for r in rows if r[key] is not None]
        if points:
            ax.plot(*zip(*points, strict=True), "o-")
        ax.set_xlabel("optimiser step")
        ax.set_title(label, fontsize=9)
        ax.set_ylim(bottom=0)
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
    except FileNotFoundError as err:
        print(f"error: {err.filename} not found: run make eval over the checkpoints first")
        return 2
    rows = curve_rows(metrics, hard)
    if not rows:
        print(f"error: no run of {report / 'metrics.csv'} is named ...step<N>")
        return 2
    write_rows(out / "learning_curve.csv", rows, list(COLUMNS))
    print(f"wrote {plot_curve(rows, out / 'learning_curve.png')} ({len(rows)} checkpoints)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
