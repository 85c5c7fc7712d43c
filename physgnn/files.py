"""Tables as CSV: atomic writes, typed reads (metrics.csv, stability.csv)."""

from __future__ import annotations

import csv
from collections.abc import Iterable
from pathlib import Path


def write_rows(path: str | Path, rows: list[dict], columns: list[str]) -> Path:
    """Write ``rows`` (dicts keyed by ``columns``; None → empty cell) to ``path`` atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        for row in rows:
            w.writerow({k: "" if row.get(k) is None else row[k] for k in columns})
    tmp.replace(path)
    return path


def read_rows(path: str | Path, floats: Iterable[str], ints: Iterable[str]) -> list[dict]:
    """Rows of a CSV with the ``floats`` and ``ints`` columns parsed (empty cell → None)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for k in floats:
            row[k] = float(row[k]) if row.get(k) not in (None, "") else None
        for k in ints:
            row[k] = int(float(row[k])) if row.get(k) not in (None, "") else None
    return rows
