"""The targets of the learned simulator's physics, one table row per run, from an eval folder.

``python -m physgnn.report.targets REPORT_DIR`` prints, as markdown, what ``make eval`` wrote
into ``REPORT_DIR`` (``metrics.csv``, ``stability.csv``, ``invariance.csv``) against the
targets of the default model (pure model: no constraint stage, no sleeping):

- test MSE and Chamfer (mean over the test rollouts), rollouts diverged on test, OOD and hard
  scenes;
- OOD: the deepest sphere–sphere overlap of any OOD rollout (diameters, target ≤ 0.25) and the
  spheres through a plane (target 0);
- ``resting_pile`` drift (radii, ≤ 1) and ``tight_pack`` depth (≤ 0.1 d) and drift (≤ 1 r);
- the invariance checks (:mod:`physgnn.evaluation.invariance`): passed of all.
"""

from __future__ import annotations

import sys
from pathlib import Path
from statistics import mean

from physgnn.files import read_rows
from physgnn.report import invariance, stability
from physgnn.report.format import fmt, md_table

HEADER = [
    "run",
    "test MSE",
    "test Chamfer",
    "diverged",
    "OOD max depth (d)",
    "OOD tunnelled",
    "resting_pile drift (r)",
    "tight_pack depth (d) / drift (r)",
    "flying block",
    "sliding row (r)",
    "collision (air, ground)",
    "bounce ≤ 10 %",
    "resting grids",
]


# the invariance checks of each column of :data:`HEADER` after the tight pack's
KINDS = (
    ("flying_block",),
    ("sliding_row",),
    ("collision", "ground_collision"),
    ("bounce",),
    ("resting_grid",),
)


def target_rows(report_dir: Path) -> list[list[str]]:
    """One markdown row per learned run of ``report_dir`` (:data:`HEADER`)."""
    metrics = read_rows(report_dir / "metrics.csv", ("mse", "chamfer"), ("diverged_at",))
    stab = stability.read_csv(report_dir / "stability.csv")
    path = report_dir / "invariance.csv"
    checks = invariance.read_csv(path) if path.exists() else []
    runs = sorted({r["run"] for r in stab if not r["run"].startswith("ground_truth")})
    return [_row(run, metrics, stab, checks) for run in runs]


def _row(run, metrics, stab, checks) -> list[str]:
    test = [r for r in metrics if r["run"] == run and r["split"] == "test"]
    mine = [r for r in stab if r["run"] == run]
    ood = [r for r in mine if r["source"] == "ood"]
    scene = {r["scene"]: r for r in mine if r["source"] == "hard"}
    gone = sum(r["diverged_at"] is not None for r in test + mine)
    pile, pack = scene.get("resting_pile", {}), scene.get("tight_pack", {})
    return [
        f"`{run}`",
        fmt(mean(r["mse"] for r in test)) if test else "–",
        fmt(mean(r["chamfer"] for r in test)) if test else "–",
        f"{gone}/{len(test) + len(mine)}",
        fmt(max((r["max_pen_sphere"] or 0.0) for r in ood)) if ood else "–",
        str(sum(int(r["tunnelled"] or 0) for r in ood)),
        fmt(pile.get("rest_drift")),
        f"{fmt(pack.get('max_pen_sphere'))} / {fmt(pack.get('rest_drift'))}",
        *(_checks([c for c in checks if c["run"] == run and c["kind"] in k]) for k in KINDS),
    ]


def _checks(rows: list[dict]) -> str:
    """``passed/all`` of one kind of invariance check, and its worst value where one row."""
    if not rows:
        return "–"
    passed = sum(r["passed"] for r in rows)
    return f"{passed}/{len(rows)}" + (f" ({fmt(rows[0]['value'])})" if len(rows) == 1 else "")


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1 or not (Path(args[0]) / "stability.csv").exists():
        print("usage: python -m physgnn.report.targets REPORT_DIR (a make eval folder)")
        return 2
    print(md_table(HEADER, target_rows(Path(args[0]))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
