"""The summary of a sweep (``python -m physgnn.train -m ...``, ``+experiment=...``): a Hydra
callback (``hydra.callbacks.sweep_summary`` in ``conf/train.yaml``) that runs once every job is
done, whichever launcher ran them (Hydra's own, joblib, submitit).

Before any job is launched, the dataset every job would read is checked once
(:func:`check_sweep_data`): a missing one is one line, not a launch of every job to fail each
on the same file. A failing job does not stop the others (:mod:`physgnn.cli`) and records its
failure in its ``run.json``. The summary reads the ``run.json`` of every job folder of the
sweep, writes ``<sweep dir>/sweep.json`` (one entry per job: folder, status, overrides,
error) and prints one line per job that did not finish; then the sweep exits with code 1 if
any did not.
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import PhysgnnError, one_line
from physgnn.files import write_json
from physgnn.overrides import parse_overrides
from physgnn.training.datamodule import check_training_data
from physgnn.training.runs import RUN_JSON, read_run_json

# A job in one of these states did its work (debug: a fast_dev_run smoke test).
DONE = ("finished", "truncated", "debug")


def _job_number(folder: Path) -> tuple[int, str]:
    head = folder.name.split("_", 1)[0]
    return (int(head) if head.isdigit() else sys.maxsize, folder.name)


def sweep_jobs(sweep_dir: Path) -> list[dict]:
    """One entry per job folder (``.hydra/`` or ``run.json`` inside) of ``sweep_dir``, in job
    order; a job without run.json failed before training started."""
    folders = [p for p in Path(sweep_dir).iterdir() if p.is_dir()] if sweep_dir.is_dir() else []
    folders = [p for p in folders if (p / ".hydra").is_dir() or (p / RUN_JSON).is_file()]
    jobs = []
    for folder in sorted(folders, key=_job_number):
        try:
            info = read_run_json(folder)
        except ValueError:  # a run.json cut short
            info = {"status": "unreadable"}
        jobs.append(
            {
                "job": folder.name,
                "status": info.get("status", "no run.json"),
                "overrides": info.get("overrides"),
                "error": info.get("error"),
                "run_dir": str(folder),
            }
        )
    return jobs


def summarize(sweep_dir: Path) -> list[dict]:
    """Write ``sweep.json`` and print the summary; returns the jobs that did not finish."""
    jobs = sweep_jobs(sweep_dir)
    counts = Counter(j["status"] for j in jobs)
    write_json(
        sweep_dir / "sweep.json", {"sweep_dir": str(sweep_dir), "counts": counts, "jobs": jobs}
    )
    failed = [j for j in jobs if j["status"] not in DONE]
    said = ", ".join(f"{n} {status}" for status, n in sorted(counts.items()))
    print(f"sweep {sweep_dir}: {len(jobs)} jobs ({said}); summary in sweep.json", file=sys.stderr)
    for job in failed:
        error = f": {job['error']}" if job["error"] else ""
        print(f"  {job['job']}: {job['status']}{error}", file=sys.stderr)
    return failed


# Keys whose sweep gives jobs other datasets: the sweep's own config then names none of them
DATA_KEYS = (
    "data",
    "+data",
    "paths",
    "datamodule.data_dir",
    "datamodule.preset",
    "variant",
    "+variant",
)


def swept_keys(config: DictConfig) -> list[str]:
    """The keys a sweep varies: ``hydra.sweeper.params`` and command-line overrides with
    several values (``model.network.M=1,2``, ``range(...)``, ``choice(...)``)."""
    keys = [str(k) for k in (OmegaConf.select(config, "hydra.sweeper.params") or {})]
    task = OmegaConf.select(config, "hydra.overrides.task") or []
    keys += [o.key for o in parse_overrides(list(task)) if o.sweep]
    return keys


def check_sweep_data(config: DictConfig) -> None:
    """The dataset of a sweep whose jobs all read the same one is there (one line and exit 2
    before any job is launched); a sweep over datasets is left to its jobs."""
    if any(k.split(".")[0] in DATA_KEYS or k in DATA_KEYS for k in swept_keys(config)):
        return
    data_dir = OmegaConf.select(config, "datamodule.data_dir")
    preset = OmegaConf.select(config, "datamodule.preset", default="")
    if data_dir is None:
        return
    try:
        check_training_data(data_dir, str(preset))
    except PhysgnnError as err:
        print(f"error: {one_line(err)}; no job of the sweep was launched", file=sys.stderr)
        sys.exit(err.exit_code)


class SweepSummary(Callback):
    """Hydra callback: :func:`check_sweep_data` before the jobs; :func:`summarize` the sweep
    at its end, exit 1 if a job failed."""

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        check_sweep_data(config)

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        sweep_dir = Path(str(config.hydra.sweep.dir))
        failed = summarize(sweep_dir)
        if failed:
            print(
                f"error: {len(failed)} job(s) of the sweep did not finish "
                f"(see {sweep_dir / 'sweep.json'})",
                file=sys.stderr,
            )
            sys.exit(1)
