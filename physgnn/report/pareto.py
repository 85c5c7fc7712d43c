"""The Pareto view: accuracy against cost (ms per frame) on the same work.

``make eval`` draws the learned runs, each trained run at its learned settings and pybullet at
each substep count, every point from the same start states and scored against the same truth
(metrics.csv; the points and the front: :mod:`physgnn.report.same_work`). ``make bench``
draws pybullet's own curve on its bench pile against a fine reference (``bench.json`` for the
frame rate, ``bench_extra.json`` for the accuracy of each substep count): a different work, so
it stays in the bench report.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from physgnn.metrics.names import PARETO, label  # noqa: E402
from physgnn.report.figures import save_figure  # noqa: E402
from physgnn.report.same_work import SETTING, Point, front, points  # noqa: E402
from physgnn.report.table import SPLITS  # noqa: E402


def pybullet_points(bench: dict, extra: dict, metric: str) -> list[Point]:
    """The bench's pybullet at each substep count: cost from ``bench['pybullet']``, accuracy
    from ``extra['pybullet_accuracy']`` (entries ``{n_spheres, substeps, <metric>}``)."""
    fps = {(e["n_spheres"], e["substeps"]): e["fps"] for e in bench.get("pybullet", [])}
    pts = []
    for e in extra.get("pybullet_accuracy", []):
        f = fps.get((e["n_spheres"], e["substeps"]))
        value = e.get(metric)
        if f is None or value is None or f <= 0:
            continue
        label = f"pybullet {e['substeps']} substeps ({e['n_spheres']} spheres)"
        pts.append(Point(label, 1000.0 / f, float(value), "pybullet"))
    return pts


def _xy(pts: list[Point]) -> tuple[list[float], list[float]]:
    return [p.ms_per_frame for p in pts], [p.error for p in pts]


def _draw(ax, points: list[Point], title: str, ylabel: str) -> None:
    """One panel: the points by kind, the diverged ones as red crosses, the frontier."""
    valid = [p for p in points if p.valid]
    on_front = front(points)
    styles = {
        "learned": dict(marker="o", color="tab:blue"),
        SETTING: dict(marker="^", color="tab:green"),
        "pybullet": dict(marker="s", color="tab:orange"),
    }
    for kind, st in styles.items():
        pts = [p for p in valid if p.kind == kind]
        if pts:
            ax.scatter(*_xy(pts), label=kind, s=22, **st)
    bad = [p for p in points if not p.valid]
    if bad:
        ax.scatter(*_xy(bad), marker="x", color="red", label="diverged (prefix)", s=30)
    if on_front:
        ax.step(*_xy(on_front), where="post", color="black", lw=1.0, label="Pareto frontier")
        ax.scatter(*_xy(on_front), s=80, facecolors="none", edgecolors="black")
    # a learned setting is named by its knob alone (its model is the learned point's); labels
    # of points close together are staggered upwards so that they do not print over each other
    for rank, p in enumerate(sorted(points, key=lambda q: (q.error, q.ms_per_frame))):
        name = p.label.split(" · ")[-1] if p.kind == SETTING else p.label
        ax.annotate(
            name,
            (p.ms_per_frame, p.error),
            fontsize=5,
            xytext=(3, 2 + 6 * (rank % 3)),
            textcoords="offset points",
        )
    _axes(ax, points, title, ylabel)


def _axes(ax, points: list[Point], title: str, ylabel: str) -> None:
    """Log axes when every point is positive (errors of exactly 0, as the engine at the truth's
    own settings can reach: a linear band below the smallest positive one), titles, labels and
    the legend."""
    positive = [p.error for p in points if p.error > 0]
    if points and all(p.ms_per_frame > 0 for p in points) and positive:
        ax.set_xscale("log")
        if len(positive) == len(points):
            ax.set_yscale("log")
        else:
            ax.set_yscale("symlog", linthresh=min(positive))
    if not points:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    ax.set_title(title, fontsize=8)
    ax.set_xlabel("ms per frame", fontsize=8)
    ax.set_ylabel(ylabel, fontsize=7)
    ax.tick_params(labelsize=7)
    if points:
        ax.legend(fontsize=6)


def plot_pareto(path: str | Path, metric: str, panels: dict[str, list[Point]], title: str) -> Path:
    """One PNG: a panel per split (``panels[split] = points``), frontier drawn in black."""
    fig, axes = plt.subplots(1, len(panels), squeeze=False, figsize=(6 * len(panels), 4.6))
    for ax, (split, pts) in zip(axes[0], panels.items(), strict=True):
        _draw(ax, pts, f"{split}: {metric} vs cost", label(metric))
    fig.suptitle(title, fontsize=8)
    return save_figure(fig, path)


SAME_WORK = (
    "Accuracy vs time on the same work: every simulator from the same start states (the first "
    "H+1 truth frames), scored against the same truth"
)


def pareto_figures(
    rows: list[dict], fig_dir: str | Path, metrics=PARETO, splits=SPLITS
) -> list[Path]:
    """Write ``fig_dir/pareto_<metric>.png`` for each metric (metrics.csv rows: the learned
    runs and pybullet's rows on their work); returns the paths written."""
    paths = []
    for metric in metrics:
        panels = {s: points(rows, s, metric) for s in splits}
        paths.append(plot_pareto(Path(fig_dir) / f"pareto_{metric}.png", metric, panels, SAME_WORK))
    return paths


def bench_figure(path: str | Path, bench: dict, extra: dict, metric: str = "mse") -> Path:
    """The bench's pybullet curve: each substep count on the bench pile against the fine
    reference (``bench.json`` and ``bench_extra.json``'s dicts)."""
    n = next((e["n_spheres"] for e in extra.get("pybullet_accuracy", [])), "?")
    title = f"pybullet on the bench pile ({n} spheres in motion) against its fine reference"
    return plot_pareto(path, metric, {"bench": pybullet_points(bench, extra, metric)}, title)
