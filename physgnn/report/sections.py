"""The tables of report.md: Table 1 of the ground truth, learned simulators against the
trivial baselines, groups of runs, sleeping off and on."""

from __future__ import annotations

from physgnn.report.format import fmt, fmt_stat, md_table
from physgnn.report.table import (
    COMPONENTS,
    SLEEP_METRICS,
    SLEEP_SCENE,
    SLEEP_SUFFIX,
    SPLITS,
    cell,
    diverged_note,
    group_rows,
    n_seeds,
    run_frame_rates,
    select,
    stat,
)

# The report's Table 1 (Blender ground truth), mean and std: (test, ood). For comparison only.
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
    header += ["frames/s (test)", "diverged"]
    body = []
    for (_, label), g in groups.items():
        line = [label, str(n_seeds(g))]
        line += [fmt_stat(stat(select(g, s), m)) for s in splits for m in metrics]
        notes = [
            f"{s}: {diverged_note(select(g, s))}" for s in splits if diverged_note(select(g, s))
        ]
        line += [fmt_stat(run_frame_rates(select(g, "test"))), "; ".join(notes) or "no"]
        body.append(line)
    return md_table(header, body)


def components_section(rows: list[dict]) -> str:
    groups = {k: g for k, g in group_rows(rows).items() if k[0] == COMPONENTS}
    if not groups:
        return (
            f"No `{COMPONENTS}` runs (train them with "
            f"`python -m physgnn.train +experiment={COMPONENTS}`)."
        )
    return group_table(groups, splits=("ood", "test"))


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
