"""``stability.csv`` (rows of :mod:`physgnn.evaluation.stability`) and the report's stability
section."""

from __future__ import annotations

from pathlib import Path

from physgnn.files import read_rows, write_rows
from physgnn.report.format import fmt, md_table

COLUMNS = [
    "run",
    "experiment",
    "source",
    "scene",
    "n_spheres",
    "n_frames",
    "start",
    "diverged_at",
    "steps_to_divergence",
    "max_pen_sphere",
    "max_pen_ground",
    "max_pen_static",
    "energy_gain",
    "rest_drift",
    "n_resting",
]
_FLOATS = ("max_pen_sphere", "max_pen_ground", "max_pen_static", "energy_gain", "rest_drift")
_INTS = ("n_spheres", "n_frames", "start", "diverged_at", "steps_to_divergence", "n_resting")


def write_csv(path, rows: list[dict]) -> Path:
    """``stability.csv`` (columns :data:`COLUMNS`; None → empty cell), written atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path) -> list[dict]:
    return read_rows(path, _FLOATS, _INTS)


def section(rows: list[dict]) -> str:
    """Markdown of the report's stability section: one table row per (scene, run)."""
    if not rows:
        return "No stability measurements (eval with `stability=true`)."
    header = [
        "scene",
        "source",
        "run",
        "frames",
        "diverged",
        "max pen. sphere",
        "max pen. ground",
        "max pen. other",
        "energy gain",
        "rest drift (radii)",
    ]
    order = sorted(
        rows, key=lambda r: (r["source"], r["scene"], r["run"] != "ground_truth", r["run"])
    )
    body = []
    for r in order:
        steps = r["steps_to_divergence"]
        diverged = (
            "no"
            if r["diverged_at"] is None
            else f"⚠ after {steps} steps (frame {r['diverged_at']})"
        )
        drift = (
            "–" if r["rest_drift"] is None else f"{fmt(r['rest_drift'])} ({r['n_resting']} at rest)"
        )
        body.append(
            [r["scene"], r["source"], f"`{r['run']}`", str(r["n_frames"]), diverged]
            + [fmt(r[k]) for k in ("max_pen_sphere", "max_pen_ground", "max_pen_static")]
            + [fmt(r["energy_gain"]), drift]
        )
    note = (
        "Penetration: the deepest intersection of the rollout over its diameter (walls and "
        "other planes are two-sided rectangles: 0.5 means a centre on the plane, i.e. "
        "passing through it). Energy gain: normalised cumulative gain of the rollout's own "
        "energy. Rest drift: largest displacement of the spheres that rest in the ground "
        "truth. A diverged rollout is measured on its finite prefix."
    )
    return note + "\n\n" + md_table(header, body)
