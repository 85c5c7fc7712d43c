"""Figures of the eval report (PNG, matplotlib Agg): sweeps, FPS, energy over time.

Plot functions take already aggregated numbers (see :mod:`physgnn.report.sweeps`) and know nothing
of runs or files other than the PNG they write.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from physgnn.files import atomic_path  # noqa: E402

LOG_METRICS = {
    "mse",
    "mse20",
    "chamfer",
    "energy_gain",
    "depth_sphere",
    "depth_ground",
    "depth_static",
}


def save_figure(fig, path: str | Path) -> Path:
    """Lay out ``fig``, write it as a PNG (atomically, folders made) and close it."""
    path = Path(path)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    return path


def plot_sweep(
    path: str | Path,
    title: str,
    xlabel: str,
    xs: list[str],
    stats: dict[tuple[str, str], list[tuple[float, float] | None]],
    diverged: dict[str, list[bool]],
    splits: list[str],
    metrics: list[str],
) -> Path:
    """Metric versus a swept setting, mean ± std error bars, one row per split.

    ``stats[(split, metric)][i]`` is (mean, std) at ``xs[i]`` or None when absent;
    ``diverged[split][i]`` marks settings where a rollout diverged (red, metrics on prefix).
    """
    fig, axes = plt.subplots(
        len(splits), len(metrics), squeeze=False, figsize=(3.2 * len(metrics), 2.6 * len(splits))
    )
    for r, split in enumerate(splits):
        for c, metric in enumerate(metrics):
            ax = axes[r, c]
            vals = stats.get((split, metric), [None] * len(xs))
            _sweep_panel(ax, metric, vals, diverged.get(split, [False] * len(xs)))
            ax.set_xticks(
                np.arange(len(xs)), xs, fontsize=7, rotation=30 if max(map(len, xs)) > 6 else 0
            )
            ax.set_title(f"{split}: {metric}", fontsize=8)
            ax.tick_params(axis="y", labelsize=7)
            if r == len(splits) - 1:
                ax.set_xlabel(xlabel, fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def _sweep_panel(ax, metric: str, vals: list, div: list[bool]) -> None:
    """One metric of one split: mean ± std per setting, red crosses where a rollout diverged."""
    pos = np.arange(len(vals))
    ok = [i for i, v in enumerate(vals) if v is not None and math.isfinite(v[0])]
    if not ok:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        return
    mean = np.array([vals[i][0] for i in ok])
    std = np.array([vals[i][1] for i in ok])
    ax.errorbar(
        pos[ok], mean, yerr=std, fmt="o-", color="tab:blue", ecolor="tab:red", capsize=3, ms=4
    )
    bad = [j for j, i in enumerate(ok) if div[i]]
    if bad:
        ax.plot(pos[ok][bad], mean[bad], "x", color="red", ms=9, mew=2, label="diverged (prefix)")
        ax.legend(fontsize=6)
    if metric in LOG_METRICS and np.all(mean > 0):
        ax.set_yscale("log")


def plot_fps(
    path: str | Path,
    labels: list[str],
    means: list[float],
    stds: list[float],
    title: str = "Rollout frames/s per configuration (test split), mean ± std over seeds",
) -> Path:
    """Horizontal bars of frames per second, mean ± std (the report's Figure 18): each seed's
    frames over its seconds, then over seeds."""
    fig, ax = plt.subplots(figsize=(6.5, 0.35 * len(labels) + 1.2))
    y = np.arange(len(labels))
    ax.barh(y, means, xerr=stds, color="tab:blue", ecolor="tab:red", capsize=3)
    ax.set_yticks(y, labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("frames per second")
    ax.set_title(title, fontsize=9)
    return save_figure(fig, path)


def plot_energy(
    path: str | Path, scenes: dict[str, dict[str, np.ndarray]], dt: dict[str, float]
) -> Path:
    """Total energy over time, one panel per scene: ``scenes[scene][label] = E [T]``.

    The label ``ground truth`` is drawn black; a shorter series is a diverged rollout's prefix.
    """
    names = sorted(scenes)
    ncol = min(2, len(names)) or 1
    nrow = max(1, math.ceil(len(names) / ncol))
    fig, axes = plt.subplots(nrow, ncol, squeeze=False, figsize=(5.5 * ncol, 3.2 * nrow))
    for ax in axes.flat[len(names) :]:
        ax.axis("off")
    for ax, name in zip(axes.flat, names, strict=False):
        for label, series in scenes[name].items():
            t = np.arange(len(series)) * dt.get(name, 1.0)
            style = dict(color="black", lw=2.0) if label == "ground truth" else dict(lw=1.0)
            ax.plot(t, series, label=label, **style)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("time (s)", fontsize=8)
        ax.set_ylabel("total energy (J)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6)
    return save_figure(fig, path)
