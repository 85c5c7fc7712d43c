"""A Hydra callback that calls a function once every job of a sweep is done, in the process
that launched them: whichever launcher ran the jobs (Hydra's own, joblib's processes,
submitit's SLURM jobs, for which that process waits), it runs once, after all of them.

``hydra.callbacks.<name>: {_target_: physgnn.cli.sweeps.AfterSweep, run: <function>}`` in a
command's config (conf/generate.yaml merges the shards of a sweep over them). A sweep with a
failed job does not run it: it names the failed jobs and exits 1 (as a train sweep does).
"""

from __future__ import annotations

import sys
import traceback
from pathlib import Path

from hydra.experimental.callback import Callback
from hydra.utils import get_method
from omegaconf import DictConfig, OmegaConf

from physgnn.cli import JOB_ERROR, USER_ERRORS, disk_error, disk_problem, fail
from physgnn.overrides import parse_overrides


def swept_values(config: DictConfig) -> dict[str, list]:
    """The values each key of a sweep's command line took (``shard=range(0,3)`` -> [0, 1, 2],
    ``data=tiny`` -> ['tiny'])."""
    task = [str(o) for o in OmegaConf.select(config, "hydra.overrides.task") or []]
    return {o.key: list(o.values) for o in parse_overrides(task)}


def failed_jobs(sweep_dir: Path) -> dict[str, str]:
    """The error of each failed job of the sweep in ``sweep_dir``, by job folder name (the
    :data:`~physgnn.cli.JOB_ERROR` its job wrote)."""
    found = sorted(Path(sweep_dir).glob(f"*/{JOB_ERROR}")) + sorted(
        Path(sweep_dir).glob(f"*/.hydra/{JOB_ERROR}")
    )
    return {
        p.parent.name if p.parent.name != ".hydra" else p.parent.parent.name: p.read_text().strip()
        for p in found
    }


def exit_if_a_job_failed(sweep_dir: Path) -> None:
    """One line per failed job, then exit 1, if a job of the sweep failed."""
    failed = failed_jobs(sweep_dir)
    for job, error in failed.items():
        print(f"  job {job}: {error}", file=sys.stderr)
    if failed:
        print(
            f"error: {len(failed)} job(s) of the sweep failed (their errors above; logs in "
            f"{sweep_dir})",
            file=sys.stderr,
        )
        sys.exit(1)


class AfterSweep(Callback):
    """``run(config, swept)`` at the end of a sweep whose jobs all succeeded (else
    :func:`exit_if_a_job_failed`; ``config``: the sweep's, ``swept``: :func:`swept_values`);
    the line it returns is printed. A user's error is one line and its
    exit code, a bug its traceback and exit code 1 (Hydra would only warn)."""

    def __init__(self, run: str) -> None:
        self.run = run

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        exit_if_a_job_failed(Path(str(config.hydra.sweep.dir)))
        try:
            line = get_method(self.run)(config, swept_values(config))
        except USER_ERRORS as err:
            fail(err)
        except Exception as err:
            if disk_problem(err):
                fail(disk_error(err))
            traceback.print_exception(err)
            sys.exit(1)
        if line:
            print(line)
