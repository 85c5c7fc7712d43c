"""Sweeps of report.md: one table and one figure per experiment, and the FPS figure."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from physgnn.report import figures
from physgnn.report.sections import group_table
from physgnn.report.table import (
    COMPONENTS,
    SPLITS,
    diverged_note,
    group_rows,
    run_frame_rates,
    select,
    stat,
)

SWEEP_METRICS = ["mse", "chamfer", "energy_gain", "depth_sphere"]
REPORT_FIGURES = {
    "ablation_H": "Figure 15",
    "ablation_M": "Figure 16",
    "ablation_connectivity": "Figure 17",
    "ablation_lambda": "λ sweep",
}


def sweep_axis(labels: list[str]) -> tuple[str, list[str]]:
    """The override keys that vary across a sweep's labels and each label's values of them."""
    parsed = [dict(item.split("=", 1) for item in lab.split() if "=" in item) for lab in labels]
    keys = sorted({k for p in parsed for k in p})
    varying = [k for k in keys if len({p.get(k) for p in parsed}) > 1]
    if not varying:
        return "configuration", labels
    xs = [",".join(str(p.get(k, "·")) for k in varying) for p in parsed]
    return ",".join(varying), xs


def _sort_key(x: str):
    try:
        return (0, float(x), x)
    except ValueError:
        return (1, 0.0, x)


def sweep_figure(path: Path, experiment: str, groups: dict) -> Path:
    labels = [label for (_, label) in groups]
    xlabel, xs = sweep_axis(labels)
    order = sorted(range(len(xs)), key=lambda i: _sort_key(xs[i]))
    gs = [list(groups.values())[i] for i in order]
    xs = [xs[i] for i in order]
    stats = {
        (s, m): [None if (v := stat(select(g, s), m)) is None else v[:2] for g in gs]
        for s in SPLITS
        for m in SWEEP_METRICS
    }
    diverged = {s: [bool(diverged_note(select(g, s))) for g in gs] for s in SPLITS}
    title = f"{experiment} ({REPORT_FIGURES.get(experiment, 'sweep')}): mean ± std over rollouts"
    return figures.plot_sweep(path, title, xlabel, xs, stats, diverged, list(SPLITS), SWEEP_METRICS)


def fps_figure(path: Path, groups: dict) -> Path | None:
    items = [(f"{e}: {c}", run_frame_rates(select(g, "test"))) for (e, c), g in groups.items()]
    items = [(k, s) for k, s in items if s is not None]
    if not items:
        return None
    return figures.plot_fps(
        path, [k for k, _ in items], [s[0] for _, s in items], [s[1] for _, s in items]
    )


def rel(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()


def sweep_sections(rows: list[dict], fig_dir: Path, root: Path) -> list[str]:
    by_exp: dict[str, dict] = defaultdict(dict)
    for key, g in group_rows(rows).items():
        if key[0] != COMPONENTS:
            by_exp[key[0]][key] = g
    if not by_exp:
        return ["No trained runs were evaluated."]
    out = []
    for exp, groups in sorted(by_exp.items()):
        text = f"### `{exp}`\n\n" + group_table(groups)
        if len(groups) > 1:
            fig = sweep_figure(fig_dir / f"sweep_{exp}.png", exp, groups)
            text += f"\n\n![{exp}]({rel(fig, root)})"
        else:
            text += "\n\n(one configuration: no sweep figure)"
        out.append(text)
    return out
