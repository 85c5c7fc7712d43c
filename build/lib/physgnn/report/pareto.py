"""The Pareto view: accuracy against cost (ms per frame) for learned simulators and pybullet.

Learned points come from the eval report's ``metrics.csv`` (one point per configuration and
split: the mean of the metric and of the FPS over its rollouts); pybullet points come from
the bench (``bench.json`` for the frame rate, ``bench_extra.json`` for the accuracy of each
substep count against the fine reference on the bench's scene). Lower is better on both axes;
the frontier is the set of points no other point beats or ties on both.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from physgnn.report.figures import save_figure  # noqa: E402
from physgnn.report.table import SPLITS, diverged_note, group_rows, select, stat  # noqa: E402

PARETO_METRICS = ("chamfer", "energy_gain", "depth_sphere", "depth_ground")
METRIC_NAMES = {
    "chamfer": "Chamfer distance (m², squared, per frame)",
    "energy_gain": "normalised cumulative energy gain",
    "depth_sphere": "penetration: mean depth sphere–sphere / diameter",
    "depth_ground": "penetration: mean depth sphere–ground / diameter",
}


@dataclass(frozen=True)
class Point:
    """One simulator on the cost/accuracy plane; ``valid`` is False for a diverged group."""

    label: str
    ms_per_frame: float
    error: float
    kind: str  # "learned" or "pybullet"
    valid: bool = True


def pareto_frontier(costs: list[float], errors: list[float]) -> list[int]:
    """Indices of the non-dominated points (minimising both), sorted by cost.

    Point i is dominated when some j has ``cost_j ≤ cost_i`` and ``error_j ≤ error_i`` with at
    least one strict; of exact duplicates the first is kept. Non-finite points are ignored.
    """
    if len(costs) != len(errors):
        raise ValueError(f"{len(costs)} costs but {len(errors)} errors")
    ok = [i for i in range(len(costs)) if math.isfinite(costs[i]) and math.isfinite(errors[i])]
    order = sorted(ok, key=lambda i: (costs[i], errors[i], i))
    front, best = [], math.inf
    for i in order:
        if errors[i] < best:
            front.append(i)
            best = errors[i]
    return front


def learned_points(rows: list[dict], split: str, metric: str) -> list[Point]:
    """One point per (experiment, configuration) of ``metrics.csv`` rows on ``split``."""
    points = []
    for (exp, label), group in group_rows(rows).items():
        sel = select(group, split)
        err, fps = stat(sel, metric), stat(sel, "fps")
        if err is None or fps is None or fps[0] <= 0:
            continue
        valid = not diverged_note(sel)
        points.append(Point(f"{exp}: {label}", 1000.0 / fps[0], err[0], "learned", valid))
    return points


def pybullet_points(bench: dict, extra: dict, metric: str) -> list[Point]:
    """pybullet at each substep count: cost from ``bench['pybullet']``, accuracy from
    ``extra['pybullet_accuracy']`` (entries ``{n_spheres, substeps, <metric>}``)."""
    fps = {(e["n_spheres"], e["substeps"]): e["fps"] for e in bench.get("pybullet", [])}
    points = []
    for e in extra.get("pybullet_accuracy", []):
        f = fps.get((e["n_spheres"], e["substeps"]))
        value = e.get(metric)
        if f is None or value is None or f <= 0:
            continue
        label = f"pybullet {e['substeps']} substeps ({e['n_spheres']} spheres)"
        points.append(Point(label, 1000.0 / f, float(value), "pybullet"))
    return points


def _xy(points: list[Point]) -> tuple[list[float], list[float]]:
    return [p.ms_per_frame for p in points], [p.error for p in points]


def _draw(ax, points: list[Point], title: str, ylabel: str) -> None:
    """One panel: the points by kind, the diverged ones as red crosses, the frontier."""
    valid = [p for p in points if p.valid]
    front = [valid[i] for i in pareto_frontier(*_xy(valid))]
    styles = {
        "learned": dict(marker="o", color="tab:blue"),
        "pybullet": dict(marker="s", color="tab:orange"),
    }
    for kind, st in styles.items():
        pts = [p for p in valid if p.kind == kind]
        if pts:
            ax.scatter(*_xy(pts), label=kind, s=22, **st)
    bad = [p for p in points if not p.valid]
    if bad:
        ax.scatter(*_xy(bad), marker="x", color="red", label="diverged (prefix)", s=30)
    if front:
        ax.step(*_xy(front), where="post", color="black", lw=1.0, label="Pareto frontier")
        ax.scatter(*_xy(front), s=80, facecolors="none", edgecolors="black")
    for p in points:
        ax.annotate(p.label, (p.ms_per_frame, p.error), fontsize=5, xytext=(3, 2),
                    textcoords="offset points")  # fmt: skip
    _axes(ax, points, title, ylabel)


def _axes(ax, points: list[Point], title: str, ylabel: str) -> None:
    """Log axes when every point is positive, titles, labels and the legend."""
    positive = [p for p in points if p.error > 0 and p.ms_per_frame > 0]
    if points and len(positive) == len(points):
        ax.set_xscale("log")
        ax.set_yscale("log")
    if not points:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    ax.set_title(title, fontsize=8)
    ax.set_xlabel("ms per frame", fontsize=8)
    ax.set_ylabel(ylabel, fontsize=7)
    ax.tick_params(labelsize=7)
    if points:
        ax.legend(fontsize=6)


def plot_pareto(path: str | Path, metric: str, panels: dict[str, list[Point]]) -> Path:
    """One PNG: a panel per split (``panels[split] = points``), frontier drawn in black."""
    fig, axes = plt.subplots(1, len(panels), squeeze=False, figsize=(6 * len(panels), 4.6))
    for ax, (split, points) in zip(axes[0], panels.items(), strict=True):
        _draw(ax, points, f"{split}: {metric} vs cost", METRIC_NAMES.get(metric, metric))
    fig.suptitle(
        "Accuracy vs time. Learned: eval rollouts (their own scenes); pybullet: "
        "bench scene against its fine reference",
        fontsize=8,
    )
    return save_figure(fig, path)


def read_bench(bench_dir: str | Path) -> tuple[dict, dict]:
    """``bench.json`` and ``bench_extra.json`` (empty dict when the extra file is absent)."""
    bench_dir = Path(bench_dir)
    bench = json.loads((bench_dir / "bench.json").read_text())
    extra_path = bench_dir / "bench_extra.json"
    extra = json.loads(extra_path.read_text()) if extra_path.exists() else {}
    return bench, extra


def pareto_figures(
    rows: list[dict],
    bench_dir: str | Path,
    fig_dir: str | Path,
    metrics=PARETO_METRICS,
    splits=SPLITS,
) -> list[Path]:
    """Write ``fig_dir/pareto_<metric>.png`` for each metric; returns the paths written."""
    bench, extra = read_bench(bench_dir)
    paths = []
    for metric in metrics:
        pyb = pybullet_points(bench, extra, metric)
        panels = {s: learned_points(rows, s, metric) + pyb for s in splits}
        paths.append(plot_pareto(Path(fig_dir) / f"pareto_{metric}.png", metric, panels))
    return paths
