"""The study report's tables, from the registry's records grouped by configuration: Table 2
(OOD) beside the report's with verdicts and p-values, and every configuration on test and OOD.
A cell is the mean ± std over seeds, ∞ where seeds diverged (:func:`cell`)."""

from __future__ import annotations

from physgnn.ablation.aggregate import checkpoint_text, divergence, over_seeds, truth_floor
from physgnn.ablation.verdicts import RULES, table2
from physgnn.report.format import fmt, md_table

# Every configuration's table: the measures of physgnn.ablation.measure, each mean ± std
COLUMNS = [
    "mse",
    "chamfer",
    "energy_error",
    "pct_sphere",
    "max_depth_sphere",
    "max_depth_plane",
    "tunnelled",
]
# Table 2's measured columns (OOD)
TABLE2 = ["mse", "chamfer", "energy_gain", "energy_error", "max_depth_sphere", "tunnelled"]


def cell(stat) -> str:
    """``mean ± std``; ``∞ (k/n seeds)`` when seeds diverged, with the finite seeds' mean."""
    if stat.seeds == 0:
        return "–"
    finite = stat.seeds - stat.diverged
    text = "" if stat.mean is None else fmt(stat.mean)
    text += f" ± {fmt(stat.std)}" if finite > 1 else ""
    if stat.diverged:
        div = f"**∞ ({stat.diverged}/{stat.seeds} seeds diverged)**"
        return f"{div}; others {text}" if text else div
    return text


def div_cell(records: list[dict], split: str) -> str:
    """``k/n`` rollouts diverged on ``split``, with the median step when some did."""
    gone, total, median = divergence(records, split)
    return f"{gone}/{total}" + (f" (median step {median:.0f})" if gone else "")


def table2_section(groups, configs) -> str:
    """Table 2 on OOD: ours beside the report's, with the verdicts and their rules."""
    header = [
        "experiment",
        "report: MSE",
        "report: Chamfer",
        "report: energy gain",
        "ours: MSE",
        "ours: Chamfer",
        "ours: energy gain",
        "ours: energy error",
        "ours: max depth (d)",
        "ours: tunnelled",
        "OOD rollouts diverged",
        "MSE − baseline's (Welch p)",
        "the report's finding",
        "verdict",
    ]

    def cells(records):
        return [cell(over_seeds(records, "ood", m)) for m in TABLE2] + [div_cell(records, "ood")]

    rows = table2(groups, configs, cells)
    truth = truth_floor([r for g in groups.values() for r in g], "ood")
    return "\n".join(
        [
            "## Table 2: OOD, ours beside the report's",
            "",
            md_table(header, rows),
            "",
            f"**Rules.** {RULES}",
            "",
            f"The ground truth's own OOD energy gain, measured the same way, is {fmt(truth)}: the "
            "target, not a floor (a model that never moves gains nothing), so the energy error "
            "|gain − truth's gain| is what is compared. Max depth: the deepest sphere–sphere "
            "overlap of a rollout over the diameter; tunnelled: spheres whose centre crossed a "
            "plane, per rollout. *learned + constraints* is the baseline's own runs rolled out "
            "with the constraint stage. The report's figures are copied from its Table 2 (its own "
            "data, budget and units), so only the findings compare, not the numbers.",
        ]
    )


def configurations_section(groups, configs) -> str:
    """Every configuration on test and on OOD, beside the truth's energy gain."""
    out = [
        "## Every configuration",
        "",
        "`energy_error` is |energy gain − the truth's|; `pct_sphere` the % of spheres "
        "intersecting another; `max_depth_*` the deepest overlap (d); `checkpoint` the "
        "validation loss of the checkpoint measured and its step (means over seeds; chosen "
        "on the validation rollout score).",
        "",
    ]
    truth = {s: truth_floor([r for g in groups.values() for r in g], s) for s in ("test", "ood")}
    for split in ("test", "ood"):
        header = ["configuration", "seeds", *COLUMNS, "rollouts diverged", "checkpoint"]
        body = []
        for config in configs:
            recs = groups.get(config.key, [])
            if not recs:
                continue
            stats = [cell(over_seeds(recs, split, m)) for m in COLUMNS]
            body.append(
                [
                    f"`{config.key}`",
                    str(len(recs)),
                    *stats,
                    div_cell(recs, split),
                    checkpoint_text(recs, "val_loss"),
                ]
            )
        out += [
            f"### {split} (ground truth's energy gain: {fmt(truth[split])})",
            "",
            md_table(header, body),
            "",
        ]
    return "\n".join(out)
