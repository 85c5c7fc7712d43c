"""``report.md`` and its figures from ``metrics.csv`` (written by :mod:`physgnn.eval`).

Rows are grouped by (experiment, configuration), the configuration being the run's Hydra
overrides without ``seed`` and ``+experiment``; every number is the mean ± std over all
rollouts of a group (trajectories × seeds), as SPEC's Metrics section asks. A diverged
rollout's metrics are on its finite prefix and its group is marked "diverged at step k".
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

from physgnn.files import read_rows, write_rows
from physgnn.metrics import PENETRATION_KEYS
from physgnn.report import figures as plots

# metrics.csv: identification columns, the metrics, then the divergence step and the speed.
METRICS = [
    "mse",
    "mse20",
    "chamfer",
    "energy_gain",
    *PENETRATION_KEYS,
    "rotation_error",
    "drift_before_hit",
    "fps",
]
COLUMNS = [
    *("run", "experiment", "overrides", "seed", "split", "trajectory", "n_spheres", "n_frames"),
    *METRICS[:-1],
    "diverged_at",
    "fps",
]
INTS = ["n_spheres", "n_frames", "diverged_at", "seed"]
REFERENCES = ("ground_truth", "static", "gravity_only")
COMPONENTS = "ablation_components"
SPLITS = ("test", "ood")
SLEEP_SUFFIX = "+sleeping"
SLEEP_SCENE = "ood_resting_hit"
# drift_before_hit: radii a sphere resting in the truth moved before the truth moves it.
SLEEP_METRICS = ("drift_before_hit", "mse", "chamfer", "energy_gain", "depth_sphere", "pct_sphere",
                 "fps")  # fmt: skip
# Overrides that do not name a configuration (train.yaml's override_dirname excludes most):
# these keys and everything under them (``trainer.devices=2``, ``+callbacks.rollout...``).
IGNORED_KEYS = ("seed", "experiment", "experiment_name", "ckpt_path", "run_dir", "trainer",
                "logger", "callbacks", "hydra", "hydra/launcher", "paths")  # fmt: skip

# The report's Table 1 (Blender ground truth), mean and std: (test, ood). For comparison only.
BLENDER_TABLE1 = {
    "energy_gain": ((2.11e-2, 1.86e-2), (2.83e-2, 5.46e-2)),
    "depth_static": ((5.91e-5, 1.56e-4), (9.31e-4, 1.86e-3)),
    "depth_ground": ((1.75e-2, 5.31e-3), (5.11e-7, 2.87e-7)),
    "depth_sphere": ((4.22e-3, 2.17e-3), (1.65e-3, 1.28e-3)),
    "pct_sphere": ((48.41, 22.97), (48.70, 49.84)),
    "pct_ground": ((10.66, 4.98), (100.0, 0.0)),
    "pct_static": ((0.198, 0.322), (8.80, 17.59)),
}
TABLE1_NAMES = {
    "energy_gain": "Normalised cumulative energy gain ↓",
    "depth_static": "Normalised mean depth (static) ↓",
    "depth_ground": "Normalised mean depth (ground) ↓",
    "depth_sphere": "Normalised mean depth (sphere) ↓",
    "pct_sphere": "% spheres intersecting (sphere) ↓",
    "pct_ground": "% spheres intersecting (ground) ↓",
    "pct_static": "% spheres intersecting (static) ↓",
}
SWEEP_METRICS = ["mse", "chamfer", "energy_gain", "depth_sphere"]
REPORT_FIGURES = {
    "ablation_H": "Figure 15",
    "ablation_M": "Figure 16",
    "ablation_connectivity": "Figure 17",
    "ablation_lambda": "λ sweep",
}


# ---------------------------------------------------------------- csv


def write_csv(path: str | Path, rows: list[dict]) -> Path:
    """Write rows (dicts keyed by ``COLUMNS``; None → empty cell) atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path: str | Path) -> list[dict]:
    """Rows of a metrics.csv with numbers parsed (empty cell → None)."""
    return read_rows(path, METRICS, INTS)


# ---------------------------------------------------------------- grouping


def config_label(overrides: str) -> str:
    """Overrides that change the model (no seed, experiment, hydra keys): ``"model.M=3"``."""
    keep = []
    for item in (overrides or "").split():
        key = item.split("=", 1)[0].lstrip("+~")
        if key in IGNORED_KEYS or key.startswith(tuple(f"{k}." for k in IGNORED_KEYS)):
            continue
        keep.append(item.lstrip("+"))
    return " ".join(keep) or "default"


def group_rows(rows: list[dict]) -> dict[tuple[str, str], list[dict]]:
    """Learned runs grouped by (experiment, configuration label); references and the extra
    sleeping rollouts (see :func:`sleeping_section`) excluded."""
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for row in rows:
        if row["experiment"] in REFERENCES or row["run"].endswith(SLEEP_SUFFIX):
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


def diverged_note(rows: list[dict]) -> str:
    """``"diverged at step k (m/n)"`` with k the earliest step, or "" when none diverged."""
    steps = [r["diverged_at"] for r in rows if r["diverged_at"] is not None]
    if not steps:
        return ""
    return f"diverged at step {min(steps)} ({len(steps)}/{len(rows)})"


def n_seeds(rows: list[dict]) -> int:
    return len({r["run"] for r in rows})


# ---------------------------------------------------------------- formatting


def fmt(x: float | None) -> str:
    if x is None or not math.isfinite(x):
        return "–"
    if x == 0:
        return "0"
    if 1e-2 <= abs(x) < 1e4:
        return f"{x:.3g}"
    return f"{x:.2e}"


def fmt_stat(s: tuple[float, float, int] | None) -> str:
    return "–" if s is None else f"{fmt(s[0])} ± {fmt(s[1])}"


def md_table(header: list[str], body: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return "\n".join(lines)


def cell(rows: list[dict], metric: str) -> str:
    """mean ± std, with the divergence mark when a rollout of these rows diverged."""
    text = fmt_stat(stat(rows, metric))
    steps = [r["diverged_at"] for r in rows if r["diverged_at"] is not None]
    return f"{text} ⚠ diverged at step {min(steps)}" if steps and text != "–" else text


# ---------------------------------------------------------------- sections


def table1(rows: list[dict]) -> str:
    """Ground truth on test and OOD beside the report's Blender figures."""
    out = []
    for run in sorted({r["run"] for r in rows if r["experiment"] == "ground_truth"}):
        gt = [r for r in rows if r["run"] == run]
        body = []
        for m, name in TABLE1_NAMES.items():
            (bt, bts), (bo, bos) = BLENDER_TABLE1[m]
            body.append(
                [
                    name,
                    fmt_stat(stat(select(gt, "test"), m)),
                    fmt_stat(stat(select(gt, "ood"), m)),
                    f"{fmt(bt)} ± {fmt(bts)}",
                    f"{fmt(bo)} ± {fmt(bos)}",
                ]
            )
        n_test, n_ood = len(select(gt, "test")), len(select(gt, "ood"))
        out.append(
            f"`{run}`: {n_test} test and {n_ood} OOD trajectories.\n\n"
            + md_table(
                [
                    "metric",
                    "ours test",
                    "ours OOD",
                    "report (Blender) test",
                    "report (Blender) OOD",
                ],
                body,
            )
        )
    return "\n\n".join(out) or "No ground-truth rows (no dataset was evaluated)."


def ood_scenes(rows: list[dict]) -> list[str]:
    return sorted({r["trajectory"] for r in rows if r["split"] == "ood"})


def baselines_table(rows: list[dict]) -> str:
    """Learned configurations vs static vs gravity_only: mse and chamfer, test and per scene."""
    methods = [(f"{e}: {c}", g) for (e, c), g in group_rows(rows).items()]
    for ref in ("static", "gravity_only"):
        ref_rows = [r for r in rows if r["experiment"] == ref]
        if ref_rows:
            methods.append((ref, ref_rows))
    if not methods:
        return "No learned or baseline rollouts to compare."
    columns = [("test", None)] + [("ood", s) for s in ood_scenes(rows)]
    header = ["method"] + [f"{s or split} {m}" for split, s in columns for m in ("mse", "chamfer")]
    body = []
    for name, g in methods:
        line = [name]
        for split, scene in columns:
            sel = select(g, split, scene)
            line += [cell(sel, "mse"), cell(sel, "chamfer")]
        body.append(line)
    return md_table(header, body) + "\n\n" + beats_summary(rows, columns)


def _mean(rows: list[dict], metric: str) -> float | None:
    s = stat(rows, metric)
    return None if s is None else s[0]


def beats_summary(rows: list[dict], columns: list[tuple[str, str | None]]) -> str:
    """One line per learned configuration: where it beats both trivial baselines."""
    lines = []
    refs = {ref: [r for r in rows if r["experiment"] == ref] for ref in ("static", "gravity_only")}
    if not all(refs.values()):
        return "(static / gravity_only rows missing: no comparison)"
    for (e, c), g in group_rows(rows).items():
        marks = []
        for split, scene in columns:
            ok = True
            for m in ("mse", "chamfer"):
                ours = _mean(select(g, split, scene), m)
                theirs = [_mean(select(refs[k], split, scene), m) for k in refs]
                if (
                    ours is None
                    or diverged_note(select(g, split, scene))
                    or any(t is not None and ours >= t for t in theirs)
                ):
                    ok = False
            marks.append(f"{scene or split} {'✓' if ok else '✗'}")
        lines.append(
            f"- `{e}: {c}` beats static and gravity_only on mse and chamfer: " + ", ".join(marks)
        )
    return "\n".join(lines)


def group_table(
    groups: dict[tuple[str, str], list[dict]],
    splits=SPLITS,
    metrics=("mse", "chamfer", "energy_gain"),
) -> str:
    header = ["configuration", "runs"] + [f"{s} {m}" for s in splits for m in metrics]
    header += ["fps (test)", "diverged"]
    body = []
    for (_, label), g in groups.items():
        line = [label, str(n_seeds(g))]
        line += [fmt_stat(stat(select(g, s), m)) for s in splits for m in metrics]
        notes = [
            f"{s}: {diverged_note(select(g, s))}" for s in splits if diverged_note(select(g, s))
        ]
        line += [fmt_stat(stat(select(g, "test"), "fps")), "; ".join(notes) or "no"]
        body.append(line)
    return md_table(header, body)


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
    return plots.plot_sweep(path, title, xlabel, xs, stats, diverged, list(SPLITS), SWEEP_METRICS)


def fps_figure(path: Path, groups: dict) -> Path | None:
    items = [(f"{e}: {c}", stat(select(g, "test"), "fps")) for (e, c), g in groups.items()]
    items = [(k, s) for k, s in items if s is not None]
    if not items:
        return None
    return plots.plot_fps(
        path, [k for k, _ in items], [s[0] for _, s in items], [s[1] for _, s in items]
    )


# ---------------------------------------------------------------- report


def _rel(path: Path, root: Path) -> str:
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
            text += f"\n\n![{exp}]({_rel(fig, root)})"
        else:
            text += "\n\n(one configuration: no sweep figure)"
        out.append(text)
    return out


def components_section(rows: list[dict]) -> str:
    groups = {k: g for k, g in group_rows(rows).items() if k[0] == COMPONENTS}
    if not groups:
        return (
            f"No `{COMPONENTS}` runs (train them with "
            f"`python -m physgnn.train +experiment={COMPONENTS}`)."
        )
    return group_table(groups, splits=("ood", "test"))


def pareto_section(
    rows: list[dict], bench_dir: str | Path | None, fig_dir: Path, root: Path
) -> str:
    """Accuracy against ms per frame (learned runs and pybullet), when ``make bench`` ran."""
    from physgnn.report import pareto

    if bench_dir is None or not (Path(bench_dir) / "bench.json").exists():
        return "No bench results (`make bench` writes them; then run `make eval` again)."
    paths = pareto.pareto_figures(rows, bench_dir, fig_dir)
    return "\n\n".join(f"![{p.stem}]({_rel(p, root)})" for p in paths)


def sleeping_section(rows: list[dict]) -> str:
    """OOD (c) rolled out by one run with sleeping off and on (runs ``X``, ``X+sleeping``)."""
    on = [r for r in rows if r["run"].endswith(SLEEP_SUFFIX) and r["trajectory"] == SLEEP_SCENE]
    if not on:
        return f"No sleeping rollout (the eval's `sleeping_compare` films {SLEEP_SCENE})."
    body = []
    for run in sorted({r["run"] for r in on}):
        base = run.removesuffix(SLEEP_SUFFIX)
        for name, sel in (("off", base), ("on", run)):
            g = [r for r in rows if r["run"] == sel and r["trajectory"] == SLEEP_SCENE]
            cells = [fmt_stat(stat(g, m)) for m in SLEEP_METRICS]
            body.append([f"`{base}`", name, *cells, diverged_note(g) or "no"])
    header = ["run", "sleeping", *SLEEP_METRICS, "diverged"]
    return md_table(header, body)


def stability_section(root: Path) -> str:
    """The stability table from ``root/stability.csv`` (written by the eval's ``stability``)."""
    from physgnn.evaluation import stability

    path = root / "stability.csv"
    if not path.exists():
        return "No stability measurements (`make eval` with `stability=true` writes them)."
    return stability.section(stability.read_csv(path))


def write_report(
    report_dir: str | Path,
    rows: list[dict] | None = None,
    bench_dir: str | Path | None = None,
    skipped: list[str] | None = None,
) -> Path:
    """Write ``report.md`` (and the sweep / FPS / Pareto figures) from ``report_dir/metrics.csv``.

    Figures the eval already wrote (``figures/energy_ood.png``, ``videos/*.gif``) are linked;
    the Pareto view needs ``bench_dir/bench.json``.
    """
    root = Path(report_dir)
    rows = read_csv(root / "metrics.csv") if rows is None else rows
    fig_dir = root / "figures"
    parts = [
        "# physgnn evaluation report",
        f"{len({r['run'] for r in rows})} runs (with the references ground_truth, static, "
        "gravity_only), metrics per rollout in `metrics.csv`. Every cell is the mean ± std "
        "over the rollouts of a group (trajectories × seeds). ⚠ marks a group where a "
        "rollout diverged: its metrics are computed on the finite prefix.",
        "## Table 1: ground truth",
        table1(rows),
        "## Learned simulators against the trivial baselines",
        baselines_table(rows),
        "## Table 2: ablation of components (OOD first)",
        components_section(rows),
        "## Experiments and sweeps",
        *sweep_sections(rows, fig_dir, root),
        f"## OOD (c) `{SLEEP_SCENE}` with sleeping off and on",
        sleeping_section(rows),
        "## Stability on hard scenes",
        stability_section(root),
    ]
    fps = fps_figure(fig_dir / "fps.png", group_rows(rows))
    parts += [
        "## Runtime (the report's Figure 18)",
        f"![fps]({_rel(fps, root)})" if fps else "No learned rollout timed.",
        "## Accuracy versus time (Pareto view)",
        pareto_section(rows, bench_dir, fig_dir, root),
    ]
    energy = fig_dir / "energy_ood.png"
    parts += [
        "## Energy over time on the OOD scenes",
        f"![energy]({_rel(energy, root)})" if energy.exists() else "No OOD energy figure.",
    ]
    videos = sorted((root / "videos").glob("*.gif"))
    parts += [
        "## Videos (ground truth left, prediction right)",
        "\n".join(f"- [{v.stem}]({_rel(v, root)})" for v in videos) or "No videos.",
    ]
    if skipped:
        parts += ["## Runs not evaluated", "\n".join(f"- {s}" for s in skipped)]
    path = root / "report.md"
    path.write_text("\n\n".join(parts) + "\n")
    return path
