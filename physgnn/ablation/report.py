"""The study report, rebuilt from the registry alone: ``<results_dir>/README.md`` (how it was
run, Table 2 beside the report's with verdicts and p-values, every configuration on test and
OOD) and the figures ``sweep_<name>.png``, ``curve_<name>.png`` (validation rollouts against
the step) and ``fps.png``. A hand-written ``discussion.md`` beside it is
linked when present."""

from __future__ import annotations

from datetime import datetime, timedelta
from pathlib import Path

from physgnn.ablation.aggregate import (
    by_config,
    checkpoint_text,
    divergence,
    mean_fps,
    mean_logged,
    over_seeds,
    truth_floor,
)
from physgnn.ablation.figures import plot_study_curves, plot_study_fps, plot_study_sweep
from physgnn.ablation.jobs import Config, current_fingerprint, study_budget
from physgnn.ablation.registry import DONE, budget_id
from physgnn.ablation.switches import switches_section
from physgnn.ablation.verdicts import RULES, table2
from physgnn.files import portable, write_text
from physgnn.report.format import fmt, md_table

FIGURE_SWEEPS = {  # sweep → (figure title, metrics)
    "ablation_H": ("History H (report Fig. 15)", ["mse", "chamfer", "energy_gain"]),
    "ablation_M": (
        "Message-passing blocks M (report Fig. 16)",
        ["mse", "chamfer", "energy_gain", "depth_sphere"],
    ),
    "ablation_connectivity": ("Connectivity (report Fig. 17)", ["chamfer", "energy_gain"]),
    "ablation_lambda": ("Energy-term weight λ", ["mse", "energy_gain", "energy_share"]),
}
FPS_SWEEPS = ("ablation_H", "ablation_M", "ablation_connectivity")
COLUMNS = [
    "mse",
    "chamfer",
    "energy_error",
    "pct_sphere",
    "max_depth_sphere",
    "max_depth_plane",
    "tunnelled",
]
TABLE2 = ["mse", "chamfer", "energy_gain", "energy_error", "max_depth_sphere", "tunnelled"]
# The report's budget: 500 epochs of its ≈ 200 000 training pairs in batches of 256.
REPORT_STEPS = "≈ 390 000"


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
    gone, total, median = divergence(records, split)
    return f"{gone}/{total}" + (f" (median step {median:.0f})" if gone else "")


def _earlier_default(shown: str) -> list[str]:
    """The page's warning when it shows the records of a default other than this code's."""
    current = current_fingerprint()
    if shown == current:
        return []
    return [
        f"> **Runs of an earlier default model** (`{shown}`), not of this code's default "
        f'(`{current}`): every figure on this page, its "Baseline" and every switch included, '
        "comes from that earlier default. `make study` trains this code's default's runs (the "
        "registry keeps both).",
        "",
    ]


def write_study_report(records: list[dict], configs: list[Config], cfg) -> Path:
    """Write README.md and the figures into ``cfg.results_dir`` from ``records``."""
    out = Path(cfg.results_dir)
    budget = study_budget(cfg)
    mine = [r for r in records if budget_id(r["budget"]) == budget_id(budget)]
    groups = by_config(mine)
    parts = [
        _header(mine, configs, cfg, budget),
        _table2(groups, configs),
        _all_configs(groups, configs),
        switches_section(groups, configs),
        _figures(out, groups, configs),
        _footer(out, cfg, len(configs) * len(cfg.seeds) - _done(mine)),
    ]
    return write_text(out / "README.md", "\n\n".join(p for p in parts if p) + "\n")


def _machine(machine: dict) -> str:
    """``cpu`` or ``cpu + gpu`` of a record's machine."""
    return f"{machine['cpu']}" + (f" + {machine['gpu']}" if machine.get("gpu") else "")


def _header(records, configs, cfg, budget) -> str:
    planned = len(configs) * len(cfg.seeds)
    done = [r for r in records if r.get("status") in DONE]
    failed = [r for r in records if r.get("status") == "failed"]
    machines = sorted({_machine(r["machine"]) for r in records if r.get("machine")})
    commits = sorted({str(r.get("commit")) for r in records})
    lines = [
        "# The ablation study: results",
        "",
        "Written by `make study` (`python -m physgnn.study`) from "
        "[`registry.jsonl`](registry.jsonl) alone; run it again to rebuild this page (runs "
        "already in the registry are not trained again).",
        "",
        *_earlier_default(budget["defaults"]),
        f"- **Plan:** {len(configs)} unique configurations of the sweeps {list(cfg.sweeps)} × "
        f"seeds {list(cfg.seeds)} = {planned} runs; **{len(done)} done**, {len(failed)} failed, "
        f"{max(0, planned - len(done))} left.",
        f"- **Budget of every run:** {budget['steps']} optimiser steps of "
        f"{budget['batch_size']} pairs (the default `make train` is 2 250; the report trained "
        f"{REPORT_STEPS}), the same for every configuration; further overrides "
        f"{list(budget.get('extra') or [])}; the default training `{budget['defaults']}` "
        "(fingerprint of conf/train.yaml's model and recipe: records of another default are "
        f"kept in the registry, not shown). {len(cfg.seeds)} seeds per configuration"
        + (
            " (5 would tighten the tests; the time on 2 CPU cores did not allow it)."
            if len(cfg.seeds) < 5
            else "."
        ),
        f"- **Measures:** every test and OOD trajectory rolled out to frame {cfg.horizon}; a "
        f"rollout diverges when a sphere is faster than {cfg.speed_factor:g}× the truth's "
        "fastest; a seed's figure is the mean over trajectories, ∞ when one of its rollouts "
        "diverged (never a prefix average); mean ± sample std over the seeds; energy gain "
        "measured alike (finite-difference velocities) for the truth and the rollouts.",
        f"- **Machine:** {', '.join(machines) or '–'}; {_threads(records)}.",
        f"- **Wall time:** {_wall(records)}. Code: commit {', '.join(commits) or '–'}.",
    ]
    if failed:
        lines.append(
            "- **Failed runs:** "
            + "; ".join(f"`{r['key']}` seed {r['seed']}: {r.get('reason')}" for r in failed)
        )
    return "\n".join(lines)


def _threads(records) -> str:
    threads = sorted({r.get("threads") for r in records if r.get("threads")})
    return f"{'/'.join(map(str, threads)) or '–'} torch thread(s) per run"


def _wall(records) -> str:
    ends, spans, total = [], [], 0.0
    for r in records:
        if r.get("date") and r.get("wall_s"):
            end = datetime.strptime(r["date"], "%Y-%m-%d %H:%M")
            ends.append(end)
            spans.append(end - timedelta(seconds=r["wall_s"]))
            total += r["wall_s"]
    if not ends:
        return "–"
    elapsed = (max(ends) - min(spans)).total_seconds()
    return (
        f"{elapsed / 60:.0f} min from the first run's start to the last run's end "
        f"({total / 60:.0f} min of runs, trained and measured)"
    )


def _table2(groups, configs) -> str:
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


def _all_configs(groups, configs) -> str:
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


def _figures(out: Path, groups, configs) -> str:
    lines = ["## Sweeps", ""]
    for sweep, (title, metrics) in FIGURE_SWEEPS.items():
        points = sorted(
            ((c.points[sweep], c) for c in configs if sweep in c.points), key=lambda p: _num(p[0])
        )
        if not points or not any(groups.get(c.key) for _, c in points):
            continue
        name = f"sweep_{sweep.removeprefix('ablation_')}.png"
        plot_study_sweep(
            out / name,
            title,
            [x for x, _ in points],
            [groups.get(c.key, []) for _, c in points],
            metrics,
        )
        lines += [f"![{title}]({name})", ""]
        curves = [(x, groups.get(c.key, [])) for x, c in points]
        if any(r.get("curve") for _, recs in curves for r in recs):
            curve = f"curve_{sweep.removeprefix('ablation_')}.png"
            plot_study_curves(out / curve, f"{title}: validation rollouts during training", curves)
            lines += [f"![{title}: learning curves]({curve})", ""]
        if sweep == "ablation_lambda":
            lines += [_energy_shares(points, groups), ""]
    fps = [
        (f"{s.removeprefix('ablation_')}={c.points[s]}", mean_fps(groups.get(c.key, [])))
        for s in FPS_SWEEPS
        for c in configs
        if s in c.points
    ]
    if any(stat.mean is not None for _, stat in fps):
        note = "per run on its own thread, two runs at a time"
        plot_study_fps(out / "fps.png", [k for k, _ in fps], [s for _, s in fps], note)
        lines += ["![Rollout FPS per configuration](fps.png)", ""]
    return "\n".join(lines)


def _energy_shares(points, groups) -> str:
    """The energy term's share of the loss per λ: as designed, λ × the penalty of the model
    trained without it ÷ that model's loss plus it, and the factor by which training with it cut
    the penalty (last epoch's means over seeds), beside the logged mean of per-batch shares."""
    base = next((groups.get(c.key, []) for x, c in points if _num(x)[1] == 0), [])
    penalty0, loss0 = mean_logged(base, "train/loss_energy"), mean_logged(base, "train/loss")
    parts = []
    for x, config in points:
        recs = groups.get(config.key, [])
        lam, logged = _num(x)[1], mean_logged(recs, "train/energy_share")
        penalty = mean_logged(recs, "train/loss_energy")
        if lam == 0 or penalty0 is None or loss0 is None:
            continue
        designed = lam * penalty0 / (loss0 + lam * penalty0)
        fell = f"{penalty0 / penalty:.3g}×" if penalty else "–"
        shown = f"{100 * logged:.2g} %" if logged is not None else "–"
        parts.append(f"| {x} | {100 * designed:.2g} % | {fell} | {shown} |")
    if not parts:
        return ""
    return "\n".join(
        [
            "The energy term's share of the loss, per λ: *as designed* is λ × the penalty of the "
            "model trained without it (λ = 0) ÷ (its loss + that), the share the term would have "
            "if the model did not learn to avoid it; *penalty cut* is λ = 0's penalty over this "
            "λ's; *logged* the last epoch's mean of per-batch shares (small once the penalty is "
            "cut).",
            "",
            "| λ | share as designed | penalty cut | logged share |",
            "|---|---|---|---|",
            *parts,
        ]
    )


def _num(x: str):
    try:
        return (0, float(x), x)
    except ValueError:
        return (1, 0.0, x)


def _done(records: list[dict]) -> int:
    return sum(r.get("status") in DONE for r in records)


def _footer(out: Path, cfg, left: int) -> str:
    trains = "nothing" if left <= 0 else f"only the {left} runs it lacks"
    lines = [
        "## Reproduce",
        "",
        "```bash",
        "make install",
        "make study   # = python -m physgnn.study; "
        "--dry-run lists the jobs and the time they will take",
        "```",
        "",
        f"A clean checkout has this registry, so `make study` trains {trains} and rewrites "
        "this page; to run the study again from scratch, move `registry.jsonl` away "
        f"(runs train under `{portable(cfg.runs_dir)}`).",
    ]
    if (out / "discussion.md").exists():
        lines += ["", "The discussion of these results: [discussion.md](discussion.md)."]
    return "\n".join(lines)
