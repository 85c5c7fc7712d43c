"""The study's registry: one JSON line per run, ``docs/results/registry.jsonl``, in the repo.

A line is written when a run is done (trained and measured, or failed): its configuration
key, seed, budget, status, machine, wall times and per-trajectory figures
(:mod:`physgnn.ablation.measure`). ``make study`` reads it to decide what is left, so a study
resumes from a clean checkout on any machine (``outputs/`` may be gone), and the study report is
rebuilt from it alone. Lines are only appended; a job measured twice keeps its latest line.
A record's key is read in today's model layout (``model.M=1``, written before the network had
a config node of its own, reads as ``model.network.M=1``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from physgnn.errors import PhysgnnError
from physgnn.overrides import parse_override
from physgnn.training.layout import key_of_today

# Statuses of a run whose result is in: trained to the budget (or stopped by the clock guard,
# ``truncated``) and measured, or exploded in training (``diverged``: a result too).
DONE = ("finished", "truncated", "diverged")


class RegistryError(PhysgnnError, ValueError):
    """A registry line that is not a run's record (one line naming the file and the line)."""


def read_registry(path: str | Path) -> list[dict]:
    """Every record, the latest per (key, seed, budget) only, in the order first written."""
    path = Path(path)
    if not path.exists():
        return []
    latest: dict[tuple, dict] = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            record = _record(line, f"{path}:{n}")
            latest[record_id(record)] = record
    return list(latest.values())


def _record(line: str, where: str) -> dict:
    """One line of the registry read as a record, else :class:`RegistryError` naming it."""
    try:
        record = json.loads(line)
        record["key"] = study_key_of_today(record["key"])
        record_id(record)
    except json.JSONDecodeError as err:
        problem = f"not a JSON line ({err.msg})"
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        problem = f"not a run record ({type(err).__name__}: {err})"
    else:
        return record
    raise RegistryError(
        f"{where}: {problem}: repair or delete that line (one JSON record per run; a run whose "
        "line is deleted is trained again by make study)"
    )


def study_key_of_today(key: str) -> str:
    """A study key (``"k=v k=v"`` sorted by key, or ``baseline``) in today's model layout."""
    parts = key.split(" ")
    today = [key_of_today(part) for part in parts]
    if today == parts:
        return key
    return " ".join(sorted(today, key=lambda part: parse_override(part).written_key))


def record_id(record: dict) -> tuple:
    return record["key"], int(record["seed"]), budget_id(record["budget"])


def budget_id(budget: dict) -> str:
    return json.dumps(budget, sort_keys=True)


def of_budget(records: list[dict], budget: dict) -> list[dict]:
    """The records run at ``budget``."""
    return [r for r in records if budget_id(r["budget"]) == budget_id(budget)]


def append_record(path: str | Path, record: dict) -> None:
    """Append one line and flush it to disk (a killed study loses no finished run)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    line = json.dumps(record, sort_keys=True, allow_nan=False) + "\n"
    with open(path, "a") as f:
        f.write(line)
        f.flush()
        os.fsync(f.fileno())


def done_ids(records: list[dict]) -> set[tuple]:
    """(key, seed, budget) of every run whose result is in (failed runs are tried again)."""
    return {record_id(r) for r in records if r.get("status") in DONE}
