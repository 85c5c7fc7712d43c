"""``invariance.csv`` (rows of :mod:`physgnn.evaluation.invariance`) and its report section."""

from __future__ import annotations

from pathlib import Path

from physgnn.files import read_rows, write_rows
from physgnn.report.format import fmt, md_table

COLUMNS = ["run", "kind", "setting", "value", "value2", "limit", "passed", "diverged_at"]
_WHAT = {
    "flying_block": "pair distance change / gap (Δv_z error / g·dt)",
    "resting_grid": "largest drift (radii)",
    "sliding_row": "largest neighbour distance change (radii)",
    "collision": "momentum change along the impact / Σ m|v|",
    "ground_collision": "momentum change along the impact / Σ m|v|",
    "bounce": "apex / e²H (|1 − x| within the limit)",
}


def write_csv(path, rows: list[dict]) -> Path:
    """``invariance.csv`` (columns :data:`COLUMNS`), written atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path) -> list[dict]:
    rows = read_rows(path, ("value", "value2", "limit"), ("diverged_at",))
    for row in rows:
        row["passed"] = row["passed"] == "True"
    return rows


def section(rows: list[dict]) -> str:
    """Markdown: one table row per (run, check), and each run's count of passed checks."""
    if not rows:
        return "No invariance checks (`make eval` writes them for every learned run)."
    header = ["run", "check", "setting", "measured", "limit", "passed"]
    body = []
    for r in rows:
        value = fmt(r["value"]) + (f" ({fmt(r['value2'])})" if r["kind"] == "flying_block" else "")
        if r["diverged_at"] is not None:
            value = f"diverged at step {r['diverged_at']}"
        body.append(
            [
                f"`{r['run']}`",
                f"{r['kind']}: {_WHAT[r['kind']]}",
                r["setting"],
                value,
                fmt(r["limit"]),
                "yes" if r["passed"] else "**no**",
            ]
        )
    runs = sorted({r["run"] for r in rows})
    tally = ", ".join(
        f"`{run}` {sum(r['passed'] for r in rows if r['run'] == run)}/"
        f"{sum(r['run'] == run for r in rows)}"
        for run in runs
    )
    note = (
        "Analytic scenes that physics decides whatever the training data held "
        "(physgnn/evaluation/invariance.py): a block flying as one, touching spheres at rest "
        "at two mass scales, a frictionless collision of masses 1 : 8, bounces over "
        f"restitutions and masses 1 kg–10 t. Checks passed: {tally}."
    )
    return note + "\n\n" + md_table(header, body)
