"""The study report, rebuilt from the registry alone: ``<results_dir>/README.md`` (how it was
run, Table 2 beside the report's with verdicts, every configuration on test and OOD) and the
figures ``sweep_<name>.png`` and ``fps.png``. A hand-written ``discussion.md`` beside it is
linked when present."""

from __future__ import annotations

from datetime import datetime, timedelta
from pathlib import Path

from omegaconf import OmegaConf

from physgnn.ablation.aggregate import (
    by_config,
    divergence,
    mean_fps,
    mean_logged,
    over_seeds,
    truth_floor,
)
from physgnn.ablation.figures import plot_study_fps, plot_study_sweep
from physgnn.ablation.jobs import Config
from physgnn.ablation.registry import DONE, budget_id
from physgnn.ablation.verdicts import table2
from physgnn.files import portable, write_text
from physgnn.report.format import fmt, md_table

FIGURE_SWEEPS = {  # sweep → (figure title, metrics)
    "ablation_H": ("History H (report Fig. 15)", ["mse", "chamfer", "energy_gain"]),
    "ablation_M": (
        "Message-passing blocks M (report Fig. 16)",
        ["mse", "chamfer", "energy_gain", "depth_sphere"],
    ),  # fmt: skip
    "ablation_connectivity": ("Connectivity (report Fig. 17)", ["chamfer", "energy_gain"]),
    "ablation_lambda": ("Energy-term weight λ", ["mse", "energy_gain", "energy_share"]),
}
FPS_SWEEPS = ("ablation_H", "ablation_M", "ablation_connectivity")
COLUMNS = ["mse", "chamfer", "energy_gain", "depth_sphere", "depth_static"]


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


def write_study_report(records: list[dict], configs: list[Config], cfg) -> Path:
    """Write README.md and the figures into ``cfg.results_dir`` from ``records``."""
    out = Path(cfg.results_dir)
    budget = {k: v for k, v in dict(cfg.budget).items()}
    mine = [r for r in records if budget_id(r["budget"]) == budget_id(_plain(cfg.budget))]
    groups = by_config(mine)
    parts = [
        _header(mine, configs, cfg, budget),
        _table2(groups, configs),
        _all_configs(groups, configs),
        _figures(out, groups, configs),
        _footer(out, cfg),
    ]
    return write_text(out / "README.md", "\n\n".join(p for p in parts if p) + "\n")


def _plain(node) -> dict:
    return OmegaConf.to_container(node, resolve=True)


def _header(records, configs, cfg, budget) -> str:
    planned = len(configs) * len(cfg.seeds)
    done = [r for r in records if r.get("status") in DONE]
    failed = [r for r in records if r.get("status") == "failed"]
    machines = sorted({f"{r['machine']['cpu']}" + (f" + {r['machine']['gpu']}" if r[
        "machine"].get("gpu") else "") for r in records if r.get("machine")})  # fmt: skip
    commits = sorted({str(r.get("commit")) for r in records})
    lines = [
        "# The ablation study: results",
        "",
        "Written by `make study` (`python -m physgnn.study`) from "
        "[`registry.jsonl`](registry.jsonl) alone; run it again to rebuild this page (runs "
        "already in the registry are not trained again).",
        "",
        f"- **Plan:** {len(configs)} unique configurations of the sweeps {list(cfg.sweeps)} × "
        f"seeds {list(cfg.seeds)} = {planned} runs; **{len(done)} done**, {len(failed)} failed, "
        f"{max(0, planned - len(done))} left.",
        f"- **Budget of every run:** {budget['steps']} optimiser steps of "
        f"{budget['batch_size']} pairs (the default `make train` is 2 250), the same for every "
        f"configuration; further overrides {list(budget.get('extra') or [])}.",
        f"- **Measures:** every test and OOD trajectory rolled out to frame {cfg.horizon}; a "
        f"rollout diverges when a sphere is faster than {cfg.speed_factor:g}× the truth's "
        "fastest; a seed's figure is the mean over trajectories, ∞ when one of its rollouts "
        "diverged (never a prefix average); mean ± sample std over the seeds; energy gain "
        "measured alike (finite-difference velocities) for the truth and the rollouts.",
        f"- **Machine:** {', '.join(machines) or '–'}; {_threads(records)}.",
        f"- **Wall time:** {_wall(records)}. Code: commit {', '.join(commits) or '–'}.",
    ]
    if failed:
        lines.append("- **Failed runs:** " + "; ".join(
            f"`{r['key']}` seed {r['seed']}: {r.get('reason')}" for r in failed))  # fmt: skip
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
    return (f"{elapsed / 60:.0f} min from the first run's start to the last run's end "
            f"({total / 60:.0f} min of runs, trained and measured)")  # fmt: skip


def _table2(groups, configs) -> str:
    header = ["experiment", "report: MSE", "report: Chamfer", "report: energy gain",
              "ours: MSE", "ours: Chamfer", "ours: energy gain", "OOD rollouts diverged",
              "the report's finding", "verdict"]  # fmt: skip
    rows = table2(groups, configs, cell, div_cell)
    floor = truth_floor([r for g in groups.values() for r in g], "ood")
    return "\n".join([
        "## Table 2: OOD, ours beside the report's",
        "",
        md_table(header, rows),
        "",
        f"The ground truth's own OOD energy gain, measured the same way, is {fmt(floor)}: the "
        "floor a perfect model would reach. The report's figures are copied from its Table 2 "
        "(its own data, budget and units), so only the findings compare, not the numbers.",
    ])  # fmt: skip


def _all_configs(groups, configs) -> str:
    out = ["## Every configuration", ""]
    floor = {s: truth_floor([r for g in groups.values() for r in g], s) for s in ("test", "ood")}
    for split in ("test", "ood"):
        header = ["configuration", "seeds", *COLUMNS, "rollouts diverged", "final loss"]
        body = []
        for config in configs:
            recs = groups.get(config.key, [])
            if not recs:
                continue
            stats = [cell(over_seeds(recs, split, m)) for m in COLUMNS]
            loss = fmt(mean_logged(recs, "train/loss_mse"))
            body.append([f"`{config.key}`", str(len(recs)), *stats, div_cell(recs, split), loss])
        out += [f"### {split} (ground truth's energy gain: {fmt(floor[split])})", "",
                md_table(header, body), ""]  # fmt: skip
    return "\n".join(out)


def _figures(out: Path, groups, configs) -> str:
    lines = ["## Sweeps", ""]
    for sweep, (title, metrics) in FIGURE_SWEEPS.items():
        points = sorted(((c.points[sweep], c) for c in configs if sweep in c.points),
                        key=lambda p: _num(p[0]))  # fmt: skip
        if not points or not any(groups.get(c.key) for _, c in points):
            continue
        name = f"sweep_{sweep.removeprefix('ablation_')}.png"
        plot_study_sweep(out / name, title, [x for x, _ in points],
                         [groups.get(c.key, []) for _, c in points], metrics)  # fmt: skip
        lines += [f"![{title}]({name})", ""]
        if sweep == "ablation_lambda":
            lines += [_energy_shares(points, groups), ""]
    fps = [(f"{s.removeprefix('ablation_')}={c.points[s]}", mean_fps(groups.get(c.key, [])))
           for s in FPS_SWEEPS for c in configs if s in c.points]  # fmt: skip
    if any(stat.mean is not None for _, stat in fps):
        note = "per run on its own thread, two runs at a time"
        plot_study_fps(out / "fps.png", [k for k, _ in fps], [s for _, s in fps], note)
        lines += ["![Rollout FPS per configuration](fps.png)", ""]
    return "\n".join(lines)


def _energy_shares(points, groups) -> str:
    """How much of the loss the energy term was, per λ (the last epoch, mean over seeds)."""
    parts = []
    for x, config in points:
        share = mean_logged(groups.get(config.key, []), "train/energy_share")
        if share is not None:
            parts.append(f"λ = {x}: {100 * share:.2g} %")
    return "Energy term's share of the last epoch's loss: " + (", ".join(parts) or "–") + "."


def _num(x: str):
    try:
        return (0, float(x), x)
    except ValueError:
        return (1, 0.0, x)


def _footer(out: Path, cfg) -> str:
    lines = ["## Reproduce", "", "```bash", "make install", "make study   # = python -m "
             "physgnn.study; --dry-run lists the jobs and the time they will take", "```", "",
             "A clean checkout has this registry, so `make study` trains nothing and rewrites "
             "this page; to run the study again from scratch, move `registry.jsonl` away "
             f"(runs train under `{portable(cfg.runs_dir)}`)."]  # fmt: skip
    if (out / "discussion.md").exists():
        lines += ["", "The discussion of these results: [discussion.md](discussion.md)."]
    return "\n".join(lines)
