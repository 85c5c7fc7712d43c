"""The study report, rebuilt from the registry alone: ``<results_dir>/README.md``, how it was
run (here), Table 2 beside the report's and every configuration on test and OOD
(:mod:`~physgnn.ablation.tables`), the default's contact switches
(:mod:`~physgnn.ablation.switches`), the sweeps and their figures
(:mod:`~physgnn.ablation.sweeps`) and how to reproduce it (here). A hand-written
``discussion.md`` beside it is linked when present."""

from __future__ import annotations

from datetime import datetime, timedelta
from pathlib import Path

from physgnn.ablation.aggregate import by_config
from physgnn.ablation.jobs import Config, current_fingerprint, study_budget
from physgnn.ablation.registry import DONE, of_budget
from physgnn.ablation.sweeps import sweeps_section
from physgnn.ablation.switches import switches_section
from physgnn.ablation.tables import configurations_section, table2_section
from physgnn.files import portable, write_text

# The report's budget: 500 epochs of its ≈ 200 000 training pairs in batches of 256.
REPORT_STEPS = "≈ 390 000"


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
    mine = of_budget(records, budget)
    groups = by_config(mine)
    parts = [
        _header(mine, configs, cfg, budget),
        table2_section(groups, configs),
        configurations_section(groups, configs),
        switches_section(groups, configs),
        sweeps_section(out, groups, configs),
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
