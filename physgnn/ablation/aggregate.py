"""From registry records to the study's figures: per-seed means, then mean ± std over seeds.

A seed's figure on a split is the mean over that split's trajectories; it is infinite when
any of its rollouts diverged before the horizon (a diverged rollout has no figures: it is not
averaged over its prefix). Over seeds: mean ± sample std of the finite seeds, and how many
seeds were infinite. Divergence is counted over all rollouts of all seeds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from physgnn.ablation.registry import DONE
from physgnn.report.format import fmt
from physgnn.report.table import frame_rate


@dataclass
class Stat:
    """Mean ± std over the finite seeds; ``diverged`` seeds of ``seeds`` were infinite."""

    mean: float | None
    std: float | None
    seeds: int
    diverged: int

    @property
    def finite(self) -> bool:
        return self.diverged == 0 and self.mean is not None


def seed_value(record: dict, split: str, metric: str) -> float | None:
    """Mean of ``metric`` over the split's trajectories (inf if one diverged); None when the
    run has no such split or did not measure ``metric`` (a record of an older study)."""
    rows = (record.get("splits") or {}).get(split) or []
    if not rows or all(metric not in r for r in rows):
        return None
    values = [r.get(metric) for r in rows]
    if any(r["diverged_at"] is not None for r in rows) or any(v is None for v in values):
        return math.inf
    return float(np.mean(values))


def over_seeds(records: list[dict], split: str, metric: str) -> Stat:
    values = [v for r in records if (v := seed_value(r, split, metric)) is not None]
    finite = [v for v in values if math.isfinite(v)]
    mean = float(np.mean(finite)) if finite else None
    std = float(np.std(finite, ddof=1)) if len(finite) > 1 else (0.0 if finite else None)
    return Stat(mean, std, len(values), len(values) - len(finite))


def divergence(records: list[dict], split: str) -> tuple[int, int, float | None]:
    """``(diverged rollouts, rollouts, median divergence step)`` over all seeds."""
    rows = [row for r in records for row in (r.get("splits") or {}).get(split) or []]
    steps = [row["diverged_at"] for row in rows if row["diverged_at"] is not None]
    return len(steps), len(rows), (float(np.median(steps)) if steps else None)


def truth_floor(records: list[dict], split: str) -> float | None:
    """The ground truth's own energy gain (same measure): what a perfect model would score."""
    for r in records:
        rows = (r.get("splits") or {}).get(split) or []
        if rows:
            return float(np.mean([row["energy_gain_truth"] for row in rows]))
    return None


def mean_checkpoint(records: list[dict], name: str) -> float | None:
    """Mean over seeds of the measured checkpoint's ``name`` (``step``, ``val_loss``)."""
    values = [
        r["checkpoint"][name] for r in records if (r.get("checkpoint") or {}).get(name) is not None
    ]
    return float(np.mean(values)) if values else None


def checkpoint_text(records: list[dict], name: str, at: str = " @ step ") -> str:
    """``mean of name`` + ``at`` + ``mean step`` of the measured checkpoints ('–' without)."""
    value, step = mean_checkpoint(records, name), mean_checkpoint(records, "step")
    if value is None:
        return "–"
    return fmt(value) + (f"{at}{step:.0f}" if step is not None else "")


def mean_logged(records: list[dict], name: str) -> float | None:
    values = [r["logged"][name] for r in records if name in (r.get("logged") or {})]
    return float(np.mean(values)) if values else None


def mean_fps(records: list[dict], split: str = "test") -> Stat:
    """Frames/s over seeds: each seed's frames over its seconds on ``split`` (its rollouts one
    scene at a time, :func:`~physgnn.report.table.frame_rate`), then mean ± sample std."""
    per_seed = []
    for r in records:
        rows = [
            {"fps": row.get("fps"), "n_frames": row.get("frames")}
            for row in (r.get("splits") or {}).get(split) or []
        ]
        rate = frame_rate(rows)
        if rate is not None:
            per_seed.append(rate)
    if not per_seed:
        return Stat(None, None, 0, 0)
    std = float(np.std(per_seed, ddof=1)) if len(per_seed) > 1 else 0.0
    return Stat(float(np.mean(per_seed)), std, len(per_seed), 0)


def by_config(records: list[dict]) -> dict[str, list[dict]]:
    """The measured records (finished or truncated) of each configuration key."""
    out: dict[str, list[dict]] = {}
    for r in records:
        if r.get("status") in DONE and r.get("splits"):
            out.setdefault(r["key"], []).append(r)
    return out
