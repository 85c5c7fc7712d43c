"""The one list of metrics (physgnn.metrics.names) names what trajectory_metrics computes, what
the views show, and what docs/EVALUATION.md defines, with the same units."""

from __future__ import annotations

import re
from pathlib import Path

from simdata import trajectory

from physgnn import metrics
from physgnn.metrics.names import BY_NAME, METRICS, PARETO, TABLE, label, scene_columns
from physgnn.report.same_work import FRONT_METRIC
from physgnn.report.table import COLUMNS

ROOT = Path(__file__).resolve().parents[1]


def test_every_key_of_trajectory_metrics_is_listed_and_nothing_else_claims_to_be():
    truth = trajectory(n=3, frames=30)
    computed = set(metrics.trajectory_metrics(truth, truth))
    listed = {m.name for m in METRICS if m.by_trajectory_metrics}
    assert computed == listed
    assert set(metrics.PENETRATION_KEYS) <= listed
    assert len(BY_NAME) == len(METRICS)  # no name twice


def test_the_views_read_the_list():
    assert COLUMNS[-len(TABLE) :] == list(TABLE)
    assert TABLE[-2:] == ("diverged_at", "fps")  # metrics.csv's last columns, as ever
    assert FRONT_METRIC in PARETO
    assert all(BY_NAME[name].lower_is_better for name in PARETO)  # the front minimises
    assert set(scene_columns(prediction=False)) == {"energy_gain", *metrics.PENETRATION_KEYS}
    assert set(scene_columns(prediction=True)) == set(TABLE) - {"fps"}
    assert label("mse20") == "position MSE at frame H + 20 (m²)"
    assert label("energy_gain") == "normalised cumulative energy gain"
    assert label("not_a_metric") == "not_a_metric"


def documented_units() -> dict[str, str]:
    """``{metric: unit}`` of docs/EVALUATION.md's "Metrics" table (a row may name several)."""
    text = (ROOT / "docs" / "EVALUATION.md").read_text(encoding="utf-8")
    section = text.split("\n## Metrics\n", 1)[1].split("\n## ", 1)[0]
    units = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("| `"):
            continue
        for name in re.findall(r"`(\w+)`", cells[0]):
            units[name] = cells[1]
    return units


def test_the_docs_define_the_listed_metrics_with_their_units():
    documented = documented_units()
    assert set(documented) == set(BY_NAME), "docs/EVALUATION.md's Metrics table and names.py"
    for name, unit in documented.items():
        assert unit == (BY_NAME[name].unit or "–"), name
