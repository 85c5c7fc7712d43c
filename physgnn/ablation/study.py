"""``make study``: plan the jobs, skip those in the registry, run the rest with progress, write
the report (:func:`run_study`)."""

from __future__ import annotations

import time
from pathlib import Path

from omegaconf import DictConfig, OmegaConf
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

from physgnn.ablation.jobs import (
    Job,
    StudyError,
    budget_overrides,
    study_budget,
    study_configs,
    study_jobs,
)
from physgnn.ablation.launch import check_launcher, launch
from physgnn.ablation.registry import (
    append_record,
    budget_id,
    done_ids,
    of_budget,
    read_registry,
)
from physgnn.ablation.report import write_study_report
from physgnn.cli import compose_config
from physgnn.data.dataset import is_dataset, presets
from physgnn.errors import PhysgnnError
from physgnn.files import code_commit
from physgnn.groundtruth.generate import generate
from physgnn.overrides import given
from physgnn.ranges import SEED, one_of
from physgnn.training.layout import key_of_today


class StudyFailed(PhysgnnError, RuntimeError):
    """Some jobs failed; the others ran and the report was written."""

    exit_code = 1


def job_spec(job: Job, cfg: DictConfig, common: list[str], rev: str | None, budget: dict) -> dict:
    """A job's spec (:func:`~physgnn.ablation.runner.run_job`); it trains in
    ``<runs_dir>/<defaults fingerprint>/<configuration>/seed<N>``."""
    folder = job.config.key.replace(" ", "__").replace("=", "-")
    return {
        "key": job.config.key,
        "overrides": job.config.overrides,
        "seed": job.seed,
        "run_dir": str(Path(cfg.runs_dir) / budget["defaults"] / folder / f"seed{job.seed}"),
        "common": common,
        "budget": budget,
        "threads": int(cfg.threads),
        "horizon": int(cfg.horizon),
        "speed_factor": float(cfg.speed_factor),
        "constraints": int(cfg.constraints),
        "commit": rev,
    }


def _cost(overrides: list[str]) -> float:
    """Relative cost of a configuration: the network's share grows with M (baseline 1)."""
    today = given([key_of_today(o) for o in overrides])  # a record's of the flat layout too
    m = int(today["model.network.M"].value) if "model.network.M" in today else 5
    m = 1 if "+variant=m1" in overrides else m
    return 0.3 + 0.7 * m / 5


def estimate_s(spec: dict, records: list[dict], cfg: DictConfig) -> float:
    """Seconds for one job: from this budget's runs in the registry, else ``cfg.estimate``."""
    same = [
        r
        for r in records
        if r.get("wall_s") and budget_id(r["budget"]) == budget_id(spec["budget"])
    ]
    mine = [r["wall_s"] for r in same if r["key"] == spec["key"]]
    if mine:
        return sum(mine) / len(mine)
    if same:
        per_cost = [r["wall_s"] / _cost(r["overrides"]) for r in same]
        return sum(per_cost) / len(per_cost) * _cost(spec["overrides"])
    steps = int(cfg.budget.steps)
    return steps * float(cfg.estimate.step_s) * _cost(spec["overrides"]) + float(
        cfg.estimate.measure_s
    )


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.0f} min" if seconds >= 90 else f"{seconds:.0f} s"


def check_study(cfg: DictConfig) -> None:
    """The study's own values, before any job is listed (a dry run included): ``seeds`` a list
    of seeds, ``preset`` a data preset of conf/data/ and the launcher's (each one line)."""
    seeds = cfg.get("seeds")
    if not OmegaConf.is_list(seeds) or len(seeds) == 0:
        raise StudyError(
            f"seeds must be a list of at least one seed, got {seeds!r} (e.g. seeds=[0,1,2])"
        )
    for i, seed in enumerate(seeds):
        SEED.check(f"seeds[{i}]", seed, "e.g. seeds=[0,1,2]", StudyError)
    allowed = one_of(*presets(), what="the training data: conf/data/<preset>.yaml")
    allowed.check("preset", cfg.get("preset"), error=StudyError)
    check_launcher(cfg.launcher)


def run_study(cfg: DictConfig) -> Path | None:
    """Run what is left of the study; returns the report's path (None for a dry run)."""
    check_study(cfg)
    console = Console(soft_wrap=True)
    configs = study_configs(list(cfg.sweeps))
    jobs = study_jobs(configs, list(cfg.seeds))
    outputs = f"paths.outputs={cfg.paths.outputs}"
    common = [*budget_overrides(cfg.budget), f"data={cfg.preset}", outputs]
    rev, budget = code_commit(), study_budget(cfg)
    specs = [job_spec(job, cfg, common, rev, budget) for job in jobs]
    records = read_registry(cfg.registry)
    done = done_ids(records)
    pending = [s for s in specs if (s["key"], s["seed"], budget_id(s["budget"])) not in done]
    n_jobs = int(cfg.launcher.n_jobs) if cfg.launcher.name == "local" else len(pending) or 1
    left_s = sum(estimate_s(s, records, cfg) for s in pending) / max(1, min(n_jobs, len(pending)))
    console.print(
        f"study: {len(configs)} configurations × {len(cfg.seeds)} seeds = {len(specs)} runs; "
        f"{len(specs) - len(pending)} in {cfg.registry}, {len(pending)} to run, "
        f"about {_minutes(left_s)} with {cfg.launcher.name} × {n_jobs}"
    )
    if cfg.dry_run:
        _print_plan(console, specs, pending, records, cfg)
        return None
    if cfg.get("report_only"):
        unlisted = unlisted_keys(records, configs, budget)
        if unlisted:
            console.print(
                f"warning: {len(unlisted)} configuration(s) of these records are not among "
                f"today's sweeps and variants ({', '.join(unlisted[:3])}"
                f"{', …' if len(unlisted) > 3 else ''}): the page leaves them out; the code of "
                "the records' default rebuilds its page whole (docs/STUDY.md)"
            )
        return write_study_report(records, configs, cfg)
    if cfg.get("fingerprint"):
        raise StudyFailed(
            "fingerprint= names the earlier default whose page report_only=true rebuilds; "
            "runs are always of this code's default: drop fingerprint= or add report_only=true"
        )
    if pending:
        _ensure_dataset(cfg, console)
    failed = _run(console, pending, records, cfg, n_jobs, configs)
    report = write_study_report(read_registry(cfg.registry), configs, cfg)
    if failed:
        raise StudyFailed(
            f"{len(failed)} of {len(pending)} runs failed ({', '.join(failed[:4])}"
            f"{', …' if len(failed) > 4 else ''}); their reasons are in {cfg.registry}; the "
            f"report {report} has the others; make study again retries the failed ones"
        )
    return report


def written(report: Path | None) -> str:
    """The line ``python -m physgnn.study`` prints."""
    return "dry run: nothing trained" if report is None else f"study report written to {report}"


def unlisted_keys(records: list[dict], configs: list, budget: dict) -> list[str]:
    """The configuration keys of the records of ``budget`` that no configuration of
    ``configs`` has: what a report of them through today's sweeps leaves out."""
    return sorted({r["key"] for r in of_budget(records, budget)} - {c.key for c in configs})


def _print_plan(console, specs, pending, records, cfg) -> None:
    todo = {id(s) for s in pending}
    for s in specs:
        state = f"to run (~{_minutes(estimate_s(s, records, cfg))})" if id(s) in todo else "done"
        console.print(f"  {s['key']:<48} seed {s['seed']}  {state}")


def _ensure_dataset(cfg: DictConfig, console) -> None:
    """Generate the training preset when its folder holds no physgnn dataset."""
    gen = compose_config("generate", [f"data={cfg.preset}", f"paths.outputs={cfg.paths.outputs}"])
    if not is_dataset(gen.data.dir):
        console.print(f"study: generating the '{cfg.preset}' dataset in {gen.data.dir} first")
        generate(gen)


def _run(console, pending, records, cfg, n_jobs, configs) -> list[str]:
    """Launch ``pending``, append each record as it comes and rewrite the report with it (a
    study stopped part-way leaves a page of what is in); returns the failed jobs' names."""
    failed, counts = [], {"finished": 0, "diverged": 0, "failed": 0}
    start = time.perf_counter()
    estimates = {id(s): estimate_s(s, records, cfg) for s in pending}
    left = sum(estimates.values())
    columns = [
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[status]}"),
    ]
    with Progress(*columns, console=console) as progress:
        task = progress.add_task("study", total=len(pending), status="")
        specs = {(s["key"], s["seed"]): s for s in pending}
        for record in launch(pending, cfg.launcher, Path(cfg.runs_dir) / "slurm"):
            append_record(cfg.registry, record)
            write_study_report(read_registry(cfg.registry), configs, cfg)
            status = record["status"] if record["status"] in counts else "finished"
            counts[status] += 1
            name = f"{record['key']} seed={record['seed']}"
            if status == "failed":
                failed.append(name)
            left -= estimates[id(specs[(record["key"], record["seed"])])]
            done = sum(counts.values())
            running = min(n_jobs, len(pending) - done)
            pace = (time.perf_counter() - start) / max(1e-9, sum(estimates.values()) - left)
            eta = max(0.0, left) * pace / max(1, min(n_jobs, len(pending)))
            progress.console.print(_line(record, name))
            summary = (
                f"{counts['finished']} done · {counts['diverged']} diverged · "
                f"{counts['failed']} failed · {running} running · ~{_minutes(eta)} left"
            )
            progress.update(task, advance=1, status=summary)
    return failed


def _line(record: dict, name: str) -> str:
    wall = f"{record.get('wall_s') or 0:.0f} s"
    if record["status"] == "failed":
        return f"  failed   {name} ({wall}): {record.get('reason')}"
    if record["status"] == "diverged":
        return f"  diverged {name} in training ({wall})"
    ood = record.get("splits", {}).get("ood", [])
    gone = sum(r["diverged_at"] is not None for r in ood)
    return f"  {record['status']:<8} {name} ({wall}; OOD rollouts diverged: {gone}/{len(ood)})"
