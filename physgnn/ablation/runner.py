"""One job of the study, start to end: train (``python -m physgnn.train`` in a subprocess, in
the job's own folder, so a job that was cut short resumes there), measure
(:func:`physgnn.ablation.measure.measure_run`) and return the registry record. Runs alike in a
local worker process and in a SLURM job (:mod:`physgnn.ablation.launch`)."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import torch

from physgnn.ablation.jobs import BASELINE
from physgnn.ablation.measure import measure_run
from physgnn.benchmark.machine import cpu_name
from physgnn.errors import one_line
from physgnn.files import portable
from physgnn.training.runs import checkpoint_of, read_run_json
from physgnn.training.tracking import run_name

TRAINED = ("finished", "truncated")


def train_command(spec: dict) -> list[str]:
    """``python -m physgnn.train`` with the job's folder, seed, budget and configuration; in the
    loggers, its name is the configuration's changes and the seed (the group: ``study``)."""
    name = run_name("study", [*spec["overrides"], f"seed={spec['seed']}"])
    return [
        sys.executable,
        "-m",
        "physgnn.train",
        f"hydra.run.dir={spec['run_dir']}",
        "experiment_name=study",
        f"run_name='{name}'",
        f"seed={spec['seed']}",
        "trainer.enable_progress_bar=false",
        "trainer.enable_model_summary=false",
        *spec["common"],
        *spec["overrides"],
    ]


def _status(run_dir: Path) -> dict:
    try:
        return read_run_json(run_dir)
    except (FileNotFoundError, ValueError):
        return {}


def _train(spec: dict, run_dir: Path) -> tuple[dict, str]:
    """Train unless the folder already holds a trained run; ``(run.json, output tail)``."""
    info = _status(run_dir)
    if info.get("status") in TRAINED + ("diverged",):
        return info, ""
    env = os.environ | {"OMP_NUM_THREADS": str(spec["threads"])}
    proc = subprocess.run(train_command(spec), env=env, capture_output=True, text=True)
    tail = "\n".join((proc.stdout + proc.stderr).strip().splitlines()[-3:])
    return _status(run_dir), tail


def _finite(value):
    """JSON has no inf/NaN: a non-finite figure is stored as None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


LOGGED = ("train/loss", "train/loss_mse", "train/loss_energy", "train/energy_share", "val/loss")
# Validation rollout metrics logged every callbacks.rollout.every_n_epochs: the learning curve.
# The rollouts stop at the score's horizon (physgnn/training/callbacks.py): "mse" is over frames
# 0..H+20, "mse20" the score's error term; records of earlier code have whole-rollout values
# and no "mse20".
CURVE = {
    "mse20": "val/mse20",
    "mse": "val/rollout_mse",
    "max_depth": "val/max_depth",
    "tunnelled": "val/tunnelled",
    "energy_gain": "val/energy_gain",
    "score": "val/rollout_score",
}
_BEST = re.compile(r"epoch(\d+)")


def _log_rows(run_dir: Path) -> list[dict]:
    """Every row of the run's CSV logs (all sessions, in order), values as floats."""
    rows = []
    for path in sorted(run_dir.glob("csv/version_*/metrics.csv")):
        with open(path, newline="") as f:
            rows += [
                {k: float(v) for k, v in row.items() if v not in (None, "")}
                for row in csv.DictReader(f)
            ]
    return rows


def logged(run_dir: Path) -> dict:
    """The first and the last epoch's value of each :data:`LOGGED` metric (``first/<name>``
    and ``<name>``): the energy term's penalty at both ends says by how much training cut it."""
    out, first = {}, {}
    for row in _log_rows(run_dir):
        for k in LOGGED:
            if k in row:
                out[k] = row[k]
                first.setdefault(f"first/{k}", row[k])
    return first | out


def learning_curve(run_dir: Path) -> list[dict]:
    """``[{"step", "mse20", "mse", "max_depth", "tunnelled", "energy_gain", "score"}]``: the
    validation rollouts of every evaluation during training (:data:`CURVE`; a metric not logged
    is None)."""
    return [
        {"step": int(row["step"]) + 1} | {k: row.get(name) for k, name in CURVE.items()}
        for row in _log_rows(run_dir)
        if "val/rollout_mse" in row
    ]


def measured_checkpoint(run_dir: Path) -> dict:
    """The checkpoint the study measures (best, else last: :func:`checkpoint_of`) with its
    epoch, step, validation loss, rollout score and the score's MSE20 from the run's log (a
    record without ``val_mse20`` is of earlier code, its score over whole rollouts)."""
    path = checkpoint_of(run_dir)
    found = _BEST.search(path.stem)
    out = {"file": path.name, "step": None, "val_loss": None, "val_score": None, "val_mse20": None}
    if not found:
        return out
    epoch = int(found.group(1))
    for row in _log_rows(run_dir):
        if int(row.get("epoch", -1)) == epoch and "val/loss" in row:
            out |= {
                "step": int(row["step"]) + 1,
                "val_loss": row["val/loss"],
                "val_score": row.get("val/rollout_score"),
                "val_mse20": row.get("val/mse20"),
            }
    return out


def machine() -> dict:
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return {"cpu": cpu_name(), "gpu": gpu, "torch": torch.__version__}


def run_job(spec: dict) -> dict:
    """Train and measure one job (``spec``: key, overrides, seed, run_dir, common overrides,
    budget, threads, horizon, speed_factor, constraints, commit); returns its registry record:
    the figures per trajectory (``splits``; the baseline's also with the constraint stage,
    ``splits_constraints``), the measured checkpoint, the logged losses and the learning
    curve."""
    torch.set_num_threads(int(spec["threads"]))
    run_dir = Path(spec["run_dir"])
    start = time.perf_counter()
    info, tail = _train(spec, run_dir)
    status = info.get("status", "failed")
    record = {
        "key": spec["key"],
        "overrides": spec["overrides"],
        "seed": spec["seed"],
        "budget": spec["budget"],
        "status": status if status in TRAINED + ("diverged",) else "failed",
        "reason": info.get("error") or (tail if status not in TRAINED else None),
        "steps": info.get("global_step"),
        "train_s": info.get("train_time_s"),
        "threads": spec["threads"],
        "machine": machine(),
        "commit": spec.get("commit"),
        "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M"),
        "horizon": spec["horizon"],
        "run_dir": portable(run_dir),
    }
    if status in TRAINED:
        record["logged"] = logged(run_dir)
        record["curve"] = learning_curve(run_dir)
        t0 = time.perf_counter()
        try:
            record["checkpoint"] = measured_checkpoint(run_dir)
            record["splits"] = measure_run(run_dir, spec["horizon"], spec["speed_factor"])
            if spec.get("constraints") and spec["key"] == BASELINE:
                record["splits_constraints"] = measure_run(
                    run_dir, spec["horizon"], spec["speed_factor"], int(spec["constraints"])
                )
        except Exception as err:  # recorded, and the study goes on with the next job
            record.update(status="failed", reason=f"measuring failed: {one_line(err)}")
        record["eval_s"] = time.perf_counter() - t0
    record["wall_s"] = time.perf_counter() - start
    return _finite(record)


def lost_job(spec: dict, err: BaseException) -> dict:
    """The record of a job whose process died before it could return one."""
    return {
        "key": spec["key"],
        "overrides": spec["overrides"],
        "seed": spec["seed"],
        "budget": spec["budget"],
        "status": "failed",
        "reason": f"job lost: {one_line(err)}",
        "run_dir": portable(spec["run_dir"]),
        "commit": spec.get("commit"),
    }


def main(argv: list[str]) -> None:
    """``python -m physgnn.ablation.runner SPEC.json RECORD.json`` (the local launcher's job
    process). SIGINT is left to the training, which saves and stops; the job then still
    writes its record (``failed``: interrupted, so the next study resumes it)."""
    # A handler, not SIG_IGN: an ignored signal would stay ignored in the training it starts.
    signal.signal(signal.SIGINT, lambda *_: None)
    spec = json.loads(Path(argv[0]).read_text())
    record = run_job(spec)
    tmp = Path(argv[1]).with_suffix(".tmp")
    tmp.write_text(json.dumps(record, allow_nan=False))
    tmp.replace(argv[1])


if __name__ == "__main__":
    main(sys.argv[1:])
