"""``bounce.csv`` (rows of :mod:`physgnn.evaluation.bounce`) and the report's bounce section."""

from __future__ import annotations

from pathlib import Path

from physgnn.files import read_rows, write_rows
from physgnn.report.format import fmt, md_table

COLUMNS = ["run", "restitution", "height", "apex", "ratio", "truth_ratio", "diverged_at"]
_FLOATS = COLUMNS[1:6]


def write_csv(path, rows: list[dict]) -> Path:
    """``bounce.csv`` (columns :data:`COLUMNS`), written atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path) -> list[dict]:
    return read_rows(path, _FLOATS, ("diverged_at",))


def section(rows: list[dict]) -> str:
    """Markdown of the bounce section: one table row per (run, restitution)."""
    if not rows:
        return "No bounce measurements (`make eval` with `bounce.height` writes them)."
    header = [
        "run",
        "restitution e",
        "drop (m)",
        "apex (m)",
        "apex / e²H, learned",
        "apex / e²H, pybullet",
    ]
    body = [
        [
            f"`{r['run']}`",
            fmt(r["restitution"]),
            fmt(r["height"]),
            fmt(r["apex"]),
            fmt(r["ratio"]),
            fmt(r["truth_ratio"]),
        ]
        for r in sorted(rows, key=lambda r: (r["run"], -r["restitution"]))
    ]
    note = (
        "One sphere per training material dropped from rest (its bottom at the drop height), "
        "rolled out from the analytic free-fall seed frames; the apex after the first bounce "
        "divided by e²·H (1 is exact; the learned simulator is told each sphere's material)."
    )
    return note + "\n\n" + md_table(header, body)
