"""``onestep.csv`` (rows of :mod:`physgnn.evaluation.onestep`) and the report's section on the
one-step error by regime: a table per split, the regimes down, the simulators across."""

from __future__ import annotations

from pathlib import Path

from physgnn.files import read_rows, write_rows
from physgnn.report.format import fmt, md_table

COLUMNS = ["run", "split", "regime", "sphere_frames", "share_frames", "mse", "share_error"]
_FLOATS = ("share_frames", "mse", "share_error")
_INTS = ("sphere_frames",)
# The regimes as the report names them (physgnn.metrics.regimes.REGIMES and "all")
LABELS = {
    "flight": "flight",
    "flight_after_contact": "flight after a contact",
    "rest": "rest",
    "plane_impact": "plane impact",
    "rolling": "rolling on a plane",
    "sphere": "sphere contact",
    "plane_sphere": "plane + sphere",
    "other": "other contact",
    "all": "**all**",
}


def write_csv(path, rows: list[dict]) -> Path:
    """``onestep.csv`` (columns :data:`COLUMNS`), written atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path) -> list[dict]:
    return read_rows(path, _FLOATS, _INTS)


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def split_table(rows: list[dict]) -> str:
    """One split's table: per regime (those with a sphere-frame) its sphere-frames and their
    share (of the first simulator), then each simulator's mean squared error and its share of
    the error."""
    runs = list(dict.fromkeys(r["run"] for r in rows))
    cell = {(r["run"], r["regime"]): r for r in rows}
    seen = {r["regime"] for r in rows if r["sphere_frames"] or r["regime"] == "all"}
    regimes = [g for g in dict.fromkeys(r["regime"] for r in rows) if g in seen]
    header = ["regime", "sphere-frames", "share", *(f"`{run}`: MSE (share)" for run in runs)]
    body = []
    for regime in regimes:
        first = cell[runs[0], regime]
        line = [
            LABELS.get(regime, regime),
            str(first["sphere_frames"]),
            _pct(first["share_frames"]),
        ]
        for run in runs:
            r = cell.get((run, regime))
            line.append("–" if r is None else f"{fmt(r['mse'])} ({_pct(r['share_error'])})")
        body.append(line)
    return md_table(header, body)


def section(rows: list[dict]) -> str:
    """Markdown of the section: a note, then a table per split."""
    if not rows:
        return "No one-step table (`make eval` with `onestep.splits` and a learned run writes it)."
    note = (
        "Each simulator predicts the next positions from every true state (never from its "
        "own); the squared position error (m²) of each sphere-frame is split by what the truth "
        "does in that frame (the same labels for every simulator: docs/EVALUATION.md, "
        '"One-step error by regime"). Per regime: its sphere-frames and their share, and per '
        "simulator the mean squared error and, in brackets, the regime's share of the "
        "simulator's summed squared error: a share of the error far above the share of frames "
        "is where the simulator loses its accuracy."
    )
    parts = [note]
    for split in dict.fromkeys(r["split"] for r in rows):
        parts += [f"**{split}**", split_table([r for r in rows if r["split"] == split])]
    return "\n\n".join(parts)
