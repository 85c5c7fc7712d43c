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
    "mean_pen_sphere",
    "tunnelled",
    "energy_gain",
    "energy_rise",
    "rest_drift",
    "n_resting",
]
_FLOATS = (
    "max_pen_sphere",
    "max_pen_ground",
    "max_pen_static",
    "mean_pen_sphere",
    "energy_gain",
    "energy_rise",
    "rest_drift",
)
_INTS = (
    "n_spheres",
    "n_frames",
    "start",
    "diverged_at",
    "steps_to_divergence",
    "n_resting",
    "tunnelled",
)


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
        "mean pen. sphere",
        "tunnelled",
        "energy gain",
        "energy rise",
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
            + [fmt(r["mean_pen_sphere"]), str(r["tunnelled"])]
            + [fmt(r["energy_gain"]), fmt(r["energy_rise"]), drift]
        )
    note = (
        "Penetration: the deepest intersection of the rollout over its diameter, and the mean "
        "sphere–sphere one (planes are one-sided: above 0.5 the centre crossed the plane; "
        "tunnelled counts those spheres). Energy gain: normalised cumulative gain of the "
        "rollout's energy, from finite-difference velocities for every row; energy rise: its "
        "largest climb above the initial energy, "
        "over the initial energy. Rest drift: largest displacement of the spheres that rest "
        "in the ground truth. A diverged rollout is measured on its finite prefix."
    )
    return note + "\n\n" + md_table(header, body)
