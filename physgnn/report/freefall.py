"""``freefall.csv`` (rows of :mod:`physgnn.evaluation.freefall`) and the report's free-fall
section."""

from __future__ import annotations

from pathlib import Path

from physgnn.files import read_rows, write_rows
from physgnn.physics.energy import G
from physgnn.report.format import fmt, md_table

COLUMNS = [
    "run",
    "height",
    "seconds",
    "dt",
    "z_true",
    "z_pred",
    "z_error",
    "z_error_pct",
    "dvz_first",
]
_FLOATS = COLUMNS[1:]


def write_csv(path, rows: list[dict]) -> Path:
    """``freefall.csv`` (columns :data:`COLUMNS`), written atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path) -> list[dict]:
    return read_rows(path, _FLOATS, ())


def section(rows: list[dict]) -> str:
    """Markdown of the free-fall section: one table row per (run, height)."""
    if not rows:
        return "No free-fall measurements (`make eval` with `freefall.heights` writes them)."
    header = [
        "run",
        "height (m)",
        "T (s)",
        "z at T, analytic",
        "z at T, learned",
        "error (m)",
        "error (% of fall)",
        "Δv_z first step (m/s)",
    ]
    body = [
        [
            f"`{r['run']}`",
            fmt(r["height"]),
            fmt(r["seconds"]),
            fmt(r["z_true"]),
            fmt(r["z_pred"]),
            fmt(r["z_error"]),
            fmt(r["z_error_pct"]),
            fmt(r["dvz_first"]),
        ]
        for r in sorted(rows, key=lambda r: (r["run"], r["height"]))
    ]
    dt = rows[0]["dt"]
    note = (
        "One sphere released at rest, rolled out from the analytic seed frames for T seconds "
        "(shorter where it would come near the ground) and compared with z(T) = h − ½gT². "
        f"In free flight the first step's Δv_z is −g·dt ({fmt(-G * dt)} m/s at "
        f"dt = {fmt(dt)} s); it must not depend on the height."
    )
    return note + "\n\n" + md_table(header, body)
