"""Accuracy against cost on the same work: the learned runs, each trained run at its own
learned settings (the rows ``<run> · <setting>`` of metrics.csv, its column ``setting``) and
pybullet at each substep count (the rows ``pybullet-<k>``), every point from the same start
states, scored against the same truth. One point per simulator and split: the mean of the
metric and of the frame rate over its rollouts. Lower is better on both axes; the front is the
set of points no other point beats or ties on both (:func:`pareto_frontier`), drawn over all.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass

from physgnn.metrics.names import PARETO
from physgnn.report.format import fmt, md_table
from physgnn.report.table import (
    ENGINE,
    SPLITS,
    config_label,
    diverged_note,
    frame_rate,
    group_rows,
    select,
    stat,
)

# The accuracy a simulator is judged on in the table (the matched-accuracy metric)
FRONT_METRIC = "mse20"
# The kind of a trained run's point at one of its learned settings
SETTING = "learned setting"


@dataclass(frozen=True)
class Point:
    """One simulator on the cost/accuracy plane; ``valid`` is False for a diverged group."""

    label: str
    ms_per_frame: float
    error: float
    kind: str  # "learned", "learned setting" (:data:`SETTING`) or "pybullet"
    valid: bool = True


def pareto_frontier(costs: list[float], errors: list[float]) -> list[int]:
    """Indices of the non-dominated points (minimising both), sorted by cost.

    Point i is dominated when some j has ``cost_j ≤ cost_i`` and ``error_j ≤ error_i`` with at
    least one strict; of exact duplicates the first is kept. Non-finite points are ignored.
    """
    if len(costs) != len(errors):
        raise ValueError(f"{len(costs)} costs but {len(errors)} errors")
    ok = [i for i in range(len(costs)) if math.isfinite(costs[i]) and math.isfinite(errors[i])]
    order = sorted(ok, key=lambda i: (costs[i], errors[i], i))
    front, best = [], math.inf
    for i in order:
        if errors[i] < best:
            front.append(i)
            best = errors[i]
    return front


def engine_groups(rows: list[dict]) -> dict[str, list[dict]]:
    """pybullet's rows by run (``pybullet-<k>...``), fewest substeps first."""
    groups: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        if row["experiment"] == ENGINE:
            groups[row["run"]].append(row)
    return dict(sorted(groups.items(), key=lambda kv: (kv[1][0].get("substeps") or 0, kv[0])))


def setting_groups(rows: list[dict]) -> dict[str, list[dict]]:
    """The learned settings' rows (column ``setting`` set) by ``"<experiment>: <configuration>
    · <setting>"``, the label of the learned runs' points with the setting after it."""
    groups: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        if row.get("setting"):
            run = f"{row['experiment'] or 'default'}: {config_label(row['overrides'])}"
            groups[f"{run} · {row['setting']}"].append(row)
    return dict(sorted(groups.items()))


def _point(label: str, rows: list[dict], metric: str, kind: str) -> Point | None:
    err, fps = stat(rows, metric), frame_rate(rows)
    if err is None or fps is None:
        return None
    return Point(label, 1000.0 / fps, err[0], kind, not diverged_note(rows))


def points(rows: list[dict], split: str, metric: str) -> list[Point]:
    """The learned configurations (one per experiment and configuration), their learned
    settings and pybullet at each substep count on ``split``, in that order; groups without
    the metric or a rate left out."""
    learned = [
        _point(f"{exp}: {label}", select(g, split), metric, "learned")
        for (exp, label), g in group_rows(rows).items()
    ]
    settings = [
        _point(name, select(g, split), metric, SETTING) for name, g in setting_groups(rows).items()
    ]
    engine = [
        _point(run, select(g, split), metric, ENGINE) for run, g in engine_groups(rows).items()
    ]
    return [p for p in learned + settings + engine if p is not None]


def front(pts: list[Point]) -> list[Point]:
    """The points of ``pts`` on the Pareto front (valid ones only), cheapest first."""
    valid = [p for p in pts if p.valid]
    return [
        valid[i] for i in pareto_frontier([p.ms_per_frame for p in valid], [p.error for p in valid])
    ]


def threads_cell(rows: list[dict]) -> str:
    """The cores ``rows`` ran on (a learned rollout's torch threads, pybullet's processes), e.g.
    ``"1"`` or ``"1, 2"``; "–" where no row says (metrics.csv files written before the
    column)."""
    counts = sorted({int(r["threads"]) for r in rows if r.get("threads") is not None})
    return ", ".join(map(str, counts)) or "–"


def split_table(rows: list[dict], split: str) -> str:
    """Every simulator on ``split``: the metrics, frames per second, ms per frame, the cores it
    ran on and whether it is on the :data:`FRONT_METRIC` front."""
    on_front = {p.label for p in front(points(rows, split, FRONT_METRIC))}
    groups = [(f"{e}: {c}", select(g, split)) for (e, c), g in group_rows(rows).items()]
    groups += [(name, select(g, split)) for name, g in setting_groups(rows).items()]
    groups += [(run, select(g, split)) for run, g in engine_groups(rows).items()]
    body = []
    for name, sel in groups:
        if not sel:
            continue
        means = [stat(sel, m) for m in PARETO]
        fps = frame_rate(sel)
        cells = [*(fmt(s[0] if s else None) for s in means), fmt(fps)]
        ms = fmt(1000.0 / fps) if fps else "–"
        note = diverged_note(sel)
        on = "✓" if name in on_front else ""
        body.append([name, *cells, ms, threads_cell(sel), on, note or ""])
    header = [
        "simulator",
        *PARETO,
        "frames/s",
        "ms/frame",
        "threads",
        f"on the {FRONT_METRIC} front",
        "diverged",
    ]
    return md_table(header, body)


def settings_on_front(rows: list[dict], split: str) -> str:
    """Which learned settings are on ``split``'s :data:`FRONT_METRIC` front, in one line ("" when
    the split has no learned setting's point)."""
    pts = points(rows, split, FRONT_METRIC)
    if not any(p.kind == SETTING for p in pts):
        return ""
    on = [f"`{p.label}`" for p in front(pts) if p.kind == SETTING]
    where = f"{split}'s {FRONT_METRIC} front"
    return (
        f"Learned settings on {where}: {', '.join(on)}."
        if on
        else f"No learned setting is on {where}."
    )


def lacks(pts: list[Point], p: Point) -> tuple[tuple | None, tuple | None]:
    """What ``p`` lacks to be on the front of ``pts``: ``(speed, accuracy)``, each
    ``(factor, the point in its way)`` or None where nothing is in its way. ``speed``: at its
    own error, ``p`` joins the front above ``factor`` × its frames/s (faster than the fastest
    valid point at least as accurate); ``accuracy``: at its own cost, below its error divided by
    ``factor`` (more accurate than the most accurate valid point at least as fast)."""
    others = [q for q in pts if q.valid and q is not p]
    accurate = [q for q in others if q.error <= p.error]
    fast = [q for q in others if q.ms_per_frame <= p.ms_per_frame]
    speed = accuracy = None
    if accurate:
        q = min(accurate, key=lambda q: q.ms_per_frame)
        speed = (p.ms_per_frame / q.ms_per_frame, q)
    if fast:
        q = min(fast, key=lambda q: q.error)
        accuracy = (p.error / q.error if q.error > 0 else math.inf, q)
    return speed, accuracy


def distance_to_front(rows: list[dict], split: str) -> str:
    """Where no learned point (a run as trained or at a setting) is on ``split``'s
    :data:`FRONT_METRIC` front, one line: the learned point nearest to it in frames/s and the
    one nearest in accuracy, by :func:`lacks` ("" when one is on it, or none is there)."""
    pts = points(rows, split, FRONT_METRIC)
    learned = [p for p in pts if p.kind != ENGINE and p.valid]
    on = {p.label for p in front(pts)}
    if not learned or any(p.label in on for p in learned):
        return ""
    needs = [(p, lacks(pts, p)) for p in learned]
    parts = []
    speed, accuracy = (_nearest(needs, which) for which in (0, 1))
    if speed:
        factor, q, p = speed
        parts.append(
            f"`{p.label}` ({FRONT_METRIC} {fmt(p.error)} at {fmt(1000.0 / p.ms_per_frame)} "
            f"frames/s) needs more than {factor:.3g}× its frames/s (`{q.label}`: {fmt(q.error)} "
            f"at {fmt(1000.0 / q.ms_per_frame)})"
        )
    if accuracy:
        factor, q, p = accuracy
        parts.append(
            f"`{p.label}` needs, at its frames/s, an {FRONT_METRIC} below {fmt(q.error)}, "
            f"{factor:.3g}× lower than its {fmt(p.error)} (`{q.label}`)"
            if math.isfinite(factor)
            else f"no {FRONT_METRIC} puts `{p.label}` on it at its frames/s (`{q.label}` is exact "
            f"and at least as fast)"
        )
    return f"Nearest to {split}'s {FRONT_METRIC} front: " + "; ".join(parts) + "." if parts else ""


def _nearest(needs: list[tuple], which: int) -> tuple | None:
    """``(factor, the point in its way, the learned point)`` of the smallest factor of
    :func:`lacks`'s ``which`` (0: speed, 1: accuracy) over ``needs`` ``[(point, lacks)]``."""
    found = [(lack[which], p) for p, lack in needs if lack[which] is not None]
    if not found:
        return None
    (factor, q), p = min(found, key=lambda item: item[0][0])
    return factor, q, p


def section(rows: list[dict]) -> str:
    """report.md's same-work section: one table per split, each with the line of the learned
    settings on its front, or why there is none, and where no learned point is on it, how far
    the nearest are (:func:`distance_to_front`)."""
    if not engine_groups(rows):
        return "No pybullet rows (no learned run was evaluated, or the eval's `pybullet` is null)."
    parts = []
    for split in SPLITS:
        if select(rows, split):
            lines = [settings_on_front(rows, split), distance_to_front(rows, split)]
            parts += [f"**{split}**", split_table(rows, split), *[ln for ln in lines if ln]]
    return "\n\n".join(parts)
