"""The default model's table, regenerated from the study's registry, each figure with the
commit it was measured on (``make default-table``).

``python -m physgnn.ablation.default_table [REGISTRY] [OUT] [KEY] [STEPS]`` reads the registry
(default ``docs/results/registry.jsonl``; a fresh run's is any ``make study
ARGS="registry=FILE ..."``) and writes ``OUT`` (default ``docs/results/default.md``): one row
per seed of configuration ``KEY`` (default ``baseline``) at ``STEPS`` optimiser steps (default:
the largest budget it was measured at), then mean ± std over the seeds. Every row names its
commit and date; rows measured on another commit than this checkout's are marked, so that
figures a change of numerics left behind are seen (tests/test_fingerprint.py fails on such a
change: re-measure, then regenerate this page).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from physgnn.ablation.aggregate import by_config, seed_value
from physgnn.ablation.jobs import current_fingerprint
from physgnn.ablation.registry import read_registry
from physgnn.errors import PhysgnnError
from physgnn.files import code_commit, portable, write_text
from physgnn.report.format import fmt

REGISTRY = "docs/results/registry.jsonl"
OUT = "docs/results/default.md"
OOD = ("ood_cubes", "ood_cubes_ramps", "ood_resting_hit", "ood_spaced_drop")
COLUMNS = [
    "seed",
    "commit",
    "date",
    "checkpoint step",
    "test MSE (m²)",
    "test Chamfer (m²)",
    *(f"{s} MSE" for s in OOD),
    "cubes max depth (d)",
    "ramps max depth (d)",
    "diverged",
]


def scene_value(record: dict, scene: str, metric: str) -> float:
    """``metric`` of the OOD trajectory ``scene`` (inf when it diverged, nan when absent)."""
    for row in (record.get("splits") or {}).get("ood") or []:
        if row["trajectory"] == scene:
            return math.inf if row["diverged_at"] is not None else float(row.get(metric, math.nan))
    return math.nan


def seed_row(record: dict) -> list[float]:
    """The figures of one seed, in :data:`COLUMNS` order after the first four."""
    values = [seed_value(record, "test", "mse"), seed_value(record, "test", "chamfer")]
    values += [scene_value(record, s, "mse") for s in OOD]
    values += [scene_value(record, s, "max_depth_sphere") for s in OOD[:2]]
    rows = [row for split in ("test", "ood") for row in record["splits"].get(split) or []]
    values.append(sum(row["diverged_at"] is not None for row in rows))
    return [math.nan if v is None else float(v) for v in values]


def records_of(records: list[dict], key: str, steps: int | None) -> list[dict]:
    """The measured records of ``key`` at ``steps`` (the largest budget when None), by seed."""
    mine = by_config(records).get(key) or []
    if not mine:
        raise PhysgnnError(f"the registry holds no measured run of {key}: run make study first")
    steps = steps or max(r["budget"]["steps"] for r in mine)
    chosen = sorted((r for r in mine if r["budget"]["steps"] == steps), key=lambda r: r["seed"])
    if not chosen:
        raise PhysgnnError(f"the registry holds no run of {key} at {steps} steps")
    return chosen


def table(records: list[dict], head: str | None) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    rows = [seed_row(r) for r in records]
    for r, values in zip(records, rows, strict=True):
        mark = "" if head is None or str(head).startswith(str(r.get("commit"))) else " *"
        step = (r.get("checkpoint") or {}).get("step")
        cells = [
            str(r["seed"]),
            f"`{r.get('commit')}`{mark}",
            str(r.get("date", "–")),
            "–" if step is None else str(step),
            *(_cell(v) for v in values),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    spreads = [_spread(column) for column in zip(*rows, strict=True)]
    lines.append("| mean ± std | | | | " + " | ".join(spreads) + " |")
    return "\n".join(lines)


def _cell(value: float) -> str:
    return "–" if math.isnan(value) else "∞ (diverged)" if math.isinf(value) else fmt(value)


def _spread(values: tuple[float, ...]) -> str:
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return "–"
    text = fmt(float(np.mean(finite)))
    text += f" ± {fmt(float(np.std(finite, ddof=1)))}" if len(finite) > 1 else ""
    gone = sum(math.isinf(v) for v in values)
    return text + (f" ({gone} of {len(values)} seeds diverged)" if gone else "")


def write_default_table(registry: str, out: str, key: str = "baseline", steps=None) -> Path:
    records = records_of(read_registry(registry), key, int(steps) if steps else None)
    head = code_commit()
    shown, current = {r["budget"].get("defaults") for r in records}, current_fingerprint()
    which = (
        "The default model"
        if shown == {current}
        else (
            f"An earlier default model (`{', '.join(sorted(map(str, shown)))}`, not this code's "
            f"`{current}`)"
        )
    )
    text = "\n".join(
        [
            f"# {which} ({key}), {records[0]['budget']['steps']} steps, per seed",
            "",
            f"Regenerated by `make default-table` from `{portable(registry)}` on a checkout at "
            f"commit `{head}`. Each row names the commit it was measured on; `*` marks a commit "
            "other than this checkout's (its figures may predate a change of numerics: re-measure "
            "with `make study` into a new registry, then `make default-table REGISTRY=...`). "
            "Depths in mean sphere diameters d; ∞: the rollout diverged before the horizon.",
            "",
            table(records, head),
            "",
        ]
    )
    return write_text(out, text)


def main(argv: list[str]) -> int:
    if len(argv) > 4:
        print("usage: python -m physgnn.ablation.default_table [REGISTRY] [OUT] [KEY] [STEPS]")
        return 2
    args = [*argv, *[None] * (4 - len(argv))]
    try:
        path = write_default_table(
            args[0] or REGISTRY, args[1] or OUT, args[2] or "baseline", args[3]
        )
    except (OSError, PhysgnnError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"default table written to {portable(path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
