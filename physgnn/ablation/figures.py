"""The study's figures (small PNGs): one metric grid per sweep and the FPS bars."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from physgnn.ablation.aggregate import Stat, seed_value, truth_floor
from physgnn.report.figures import plot_fps, plt, save_figure

SPLITS = ("test", "ood")
LABELS = {
    "mse": "position MSE (m²)",
    "chamfer": "Chamfer (m²)",
    "energy_gain": "energy gain",
    "depth_sphere": "sphere overlap (d)",
    "energy_share": "energy term / loss",
}


def plot_study_sweep(
    path: Path, title: str, xs: list[str], groups: list[list[dict]], metrics: list[str]
) -> Path:
    """Rows test/OOD, one column per metric; per setting ``xs[i]`` (records ``groups[i]``): each
    finite seed a grey dot, their mean a blue line; seeds whose rollouts diverged before the
    horizon a red × at the top with their count; the ground truth's energy gain dashed (the
    floor of a perfect model). ``energy_share`` (the logged share of the
    energy term in the loss) is drawn once, in the first row."""
    fig, axes = plt.subplots(2, len(metrics), squeeze=False, figsize=(2.7 * len(metrics), 4.6))
    pos = np.arange(len(xs))
    for r, split in enumerate(SPLITS):
        for c, metric in enumerate(metrics):
            ax = axes[r, c]
            if metric == "energy_share":
                _share_panel(ax, pos, groups, show=r == 0)
            else:
                _metric_panel(ax, pos, [[seed_value(x, split, metric) for x in g] for g in groups])
            if metric == "energy_gain":
                floor = truth_floor([x for g in groups for x in g], split)
                if floor is not None:
                    ax.axhline(floor, ls="--", color="k", lw=0.8, label="ground truth")
                    ax.legend(fontsize=6, loc="lower right")
            ax.set_xticks(pos, xs, fontsize=7)
            ax.tick_params(axis="y", labelsize=7)
            ax.set_title(f"{split}: {LABELS.get(metric, metric)}", fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def _metric_panel(ax, pos: np.ndarray, values: list[list[float | None]]) -> None:
    means = []
    for x, vals in zip(pos, values, strict=True):
        finite = [v for v in vals if v is not None and math.isfinite(v)]
        ax.plot([x] * len(finite), finite, ".", color="0.6", ms=5)
        means.append(np.mean(finite) if finite else np.nan)
        gone = sum(v is not None and not math.isfinite(v) for v in vals)
        if gone:
            ax.plot(x, 1.0, "x", color="red", ms=8, mew=2, transform=ax.get_xaxis_transform())
            ax.annotate(
                f"{gone}/{len(vals)} div.",
                (x, 0.93),
                xycoords=("data", "axes fraction"),
                ha="center",
                fontsize=6,
                color="red",
            )
    ax.plot(pos, means, "o-", color="tab:blue", ms=4)
    finite_all = [v for vals in values for v in vals if v is not None and math.isfinite(v)]
    if finite_all and min(finite_all) > 0 and max(finite_all) / min(finite_all) > 100:
        ax.set_yscale("log")


def _share_panel(ax, pos: np.ndarray, groups: list[list[dict]], show: bool) -> None:
    if not show:
        ax.axis("off")
        return
    for x, group in zip(pos, groups, strict=True):
        shares = [
            r["logged"]["train/energy_share"]
            for r in group
            if "train/energy_share" in (r.get("logged") or {})
        ]
        ax.plot([x] * len(shares), [100 * s for s in shares], "o", color="tab:green", ms=4)
    ax.set_ylabel("% of the loss (last epoch)", fontsize=7)


def plot_study_fps(path: Path, labels: list[str], stats: list[Stat], note: str) -> Path:
    """Test-split rollout FPS per configuration, mean ± std over seeds (report Figure 18)."""
    keep = [(lab, s) for lab, s in zip(labels, stats, strict=True) if s.mean is not None]
    return plot_fps(
        path,
        [lab for lab, _ in keep],
        [s.mean for _, s in keep],
        [s.std or 0.0 for _, s in keep],
        title=f"Rollout FPS, test split ({note})",
    )


# The validation rollouts stop at the score's horizon: MSE20 is the error panel; records of
# earlier code (whole rollouts, no MSE20) draw their whole-rollout MSE instead.
CURVE_PANELS = (
    ("mse20", "validation MSE20 (m²)"),
    ("max_depth", "max depth (d)"),
    ("energy_gain", "energy gain"),
)
WHOLE_MSE_PANEL = ("mse", "validation rollout MSE (m²)")


def plot_study_curves(path: Path, title: str, curves: list[tuple[str, list[dict]]]) -> Path:
    """One panel per :data:`CURVE_PANELS` metric against the optimiser step, one line per
    setting (``curves``: ``(label, records)``): the mean over its seeds of the validation
    rollouts logged during training (each record's ``curve``), at the steps all seeds share;
    the whole-rollout MSE in the first panel where no record has MSE20 (earlier code)."""
    points = [p for _, records in curves for r in records for p in r.get("curve") or []]
    panels = CURVE_PANELS
    if all(p.get("mse20") is None for p in points):
        panels = (WHOLE_MSE_PANEL, *CURVE_PANELS[1:])
    fig, axes = plt.subplots(1, len(panels), figsize=(3.3 * len(panels), 3))
    for ax, (metric, label) in zip(axes, panels, strict=True):
        for name, records in curves:
            steps, means = mean_curve(records, metric)
            if steps:
                ax.plot(steps, means, "o-", ms=3, label=name)
        ax.set_xlabel("optimiser step", fontsize=7)
        ax.set_title(label, fontsize=8)
        ax.tick_params(labelsize=7)
        # the untrained first evaluation is orders of magnitude above the rest
        log = metric in ("mse", "mse20")
        ax.set_yscale("log") if log else ax.set_yscale("symlog", linthresh=0.01)
    axes[0].legend(fontsize=6)
    fig.suptitle(title, fontsize=9)
    return save_figure(fig, path)


def mean_curve(records: list[dict], metric: str) -> tuple[list[int], list[float]]:
    """``(steps, means)``: ``metric`` averaged over the records at each step every record
    logged with a finite value."""
    per_seed = [
        {
            p["step"]: p[metric]
            for p in r.get("curve") or []
            if p.get(metric) is not None and math.isfinite(p[metric])
        }
        for r in records
    ]
    per_seed = [c for c in per_seed if c]
    if not per_seed:
        return [], []
    steps = sorted(set.intersection(*(set(c) for c in per_seed)))
    return steps, [float(np.mean([c[s] for c in per_seed])) for s in steps]
