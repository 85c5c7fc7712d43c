"""Table 2 of the report (OOD, six experiments) beside ours, each of its findings judged by a
stated rule that uses the seeds (:data:`RULES`, printed on the study page).

A seed's figure is its mean over the OOD trajectories; two configurations are compared with
Welch's t-test over their seeds' figures (two-sided, significance level :data:`ALPHA`); where
seeds diverged, by the diverged share of rollouts (Fisher exact test). Each finding is then
*reproduced*, *not reproduced*, *inconclusive at this budget* or *not comparable*.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from physgnn.ablation.aggregate import divergence, seed_value
from physgnn.ablation.jobs import Config

ALPHA = 0.05
SPLIT = "ood"
SWEEP_2 = "ablation_components"  # the sweep whose points are Table 2's rows

# ablation_components name → (row, report MSE, Chamfer, energy gain, finding)
REPORT_TABLE2 = {
    "baseline": ("Baseline", "3.36e5 ± 3.10e5", "1.25e6 ± 1.03e6", "0.24 ± 0.24",
                 "best of the table"),
    "m1": ("M = 1", "4.79e6 ± 6.56e6", "1.48e7 ± 2.03e7", "5.93e33 ± 1.03e34", "diverges"),
    "epsilon": ("ε-connectivity", "7.77e23 ± 1.35e24", "2.33e24 ± 4.04e24",
                "7.66e20 ± 1.33e21", "diverges"),
    "h0": ("H = 0", "1.19e9 ± 1.68e9", "3.56e9 ± 5.03e9", "4.76e33 ± 8.24e33", "diverges"),
    "energy": ("W/ regularization", "7.63e5 ± 6.82e5", "3.96e6 ± 3.59e6", "0.38 ± 0.26",
               "worse than the baseline"),
    "no_noise": ("w/o training noise", "9.55e21 ± 1.65e22", "2.87e22 ± 4.96e22",
                 "2.63e19 ± 4.55e19", "diverges"),
}  # fmt: skip
EXTRA_ROWS = {"no_third_law": "without the third law", "gns": "GNS-style baseline"}
CONSTRAINED_ROW = "learned + constraints"

RULES = (
    f"Each seed's figure is its mean over the OOD trajectories; a difference to the baseline "
    f"is tested with Welch's t-test over the seeds (two-sided; significant when p < {ALPHA}); "
    "where seeds diverged, the diverged share of OOD rollouts is compared instead (two-sided "
    f"Fisher exact test, p < {ALPHA}). *Diverges*: "
    "reproduced when a larger share of its OOD rollouts diverged than of the baseline's "
    f"(one-sided Fisher exact test over all rollouts, p < {ALPHA}); not reproduced when none "
    "diverged; inconclusive at this budget otherwise. *Best of the table*: not reproduced "
    "when another of the report's rows has a significantly lower OOD MSE; reproduced when the "
    "baseline's is significantly lower than each of theirs; inconclusive at this budget "
    "otherwise. *Worse than the baseline* (with the energy term): not comparable, since our "
    "λ weighs metres of height per Σmg and the report's λ = 0.01 weighs joules; the "
    "difference is shown all the same."
)


def seed_figures(records: list[dict], metric: str = "mse") -> list[float]:
    """Each seed's OOD figure (``inf`` for a seed whose rollouts diverged)."""
    return [v for r in records if (v := seed_value(r, SPLIT, metric)) is not None]


def welch_p(a: list[float], b: list[float]) -> float | None:
    """Two-sided Welch t-test p of two sets of finite seed figures; None with fewer than two
    seeds on a side or no spread at all (0 when the constant sets differ)."""
    if len(a) < 2 or len(b) < 2:
        return None
    if np.std(a) == 0 and np.std(b) == 0:
        return None if np.mean(a) == np.mean(b) else 0.0
    return float(stats.ttest_ind(a, b, equal_var=False).pvalue)


def difference(mine: list[dict], base: list[dict], metric: str = "mse") -> tuple[float, float]:
    """``(mean − baseline mean, p)`` of the seeds' OOD ``metric`` (p NaN when untestable).
    When a seed of either diverged, the means are ±∞ (the side that diverged more often is
    worse) and p is the two-sided Fisher exact test of the diverged share of rollouts."""
    a, b = seed_figures(mine, metric), seed_figures(base, metric)
    if all(map(math.isfinite, a + b)):
        p = welch_p(a, b)
        return float(np.mean(a) - np.mean(b)), math.nan if p is None else p
    gone, total, _ = divergence(mine, SPLIT)
    b_gone, b_total, _ = divergence(base, SPLIT)
    p = stats.fisher_exact([[gone, total - gone], [b_gone, b_total - b_gone]]).pvalue
    worse_side = gone / max(total, 1) - b_gone / max(b_total, 1)
    return (math.inf if worse_side >= 0 else -math.inf), float(p)


def diverges(mine: list[dict], base: list[dict]) -> str:
    gone, total, _ = divergence(mine, SPLIT)
    b_gone, b_total, _ = divergence(base, SPLIT)
    if not gone:
        return f"not reproduced: 0/{total} OOD rollouts diverged"
    p = stats.fisher_exact([[gone, total - gone], [b_gone, b_total - b_gone]], "greater").pvalue
    if p < ALPHA:
        return f"reproduced ({gone}/{total} diverged vs {b_gone}/{b_total}, p = {p:.2g})"
    return (
        f"inconclusive at this budget: {gone}/{total} diverged vs the baseline's "
        f"{b_gone}/{b_total} (p = {p:.2g})"
    )


def worse(mine: list[dict], base: list[dict]) -> str:
    return "not comparable: λ on height per Σmg here, on joules in the report"


def best(groups: dict[str, list[dict]], keys: dict[str, str]) -> str:
    """The baseline against every other of the report's rows on OOD MSE."""
    base = groups.get(keys.get("baseline", ""), [])
    base_key = keys.get("baseline")
    others = {n: groups[k] for n, k in keys.items() if k != base_key and groups.get(k)}
    if not base or not others:
        return "not comparable: no baseline or no other row"
    tests = {name: difference(recs, base) for name, recs in others.items()}
    lower = [f"{n} (p = {p:.2g})" for n, (d, p) in tests.items() if d < 0 and p < ALPHA]
    if lower:
        return "not reproduced: lower OOD MSE for " + ", ".join(lower)
    if all(d > 0 and p < ALPHA for d, p in tests.values()):
        return "reproduced (every other row significantly higher)"
    p_min = min((p for _, p in tests.values() if not math.isnan(p)), default=math.nan)
    if math.isnan(p_min):
        return "inconclusive at this budget: too few seeds to test"
    return f"inconclusive at this budget: no difference significant (smallest p = {p_min:.2g})"


def constrained(records: list[dict]) -> list[dict]:
    """The baseline's records measured with the constraint stage, as records of their own."""
    return [r | {"splits": r["splits_constraints"]} for r in records if r.get("splits_constraints")]


def table2(groups: dict[str, list[dict]], configs: list[Config], cells) -> list[list]:
    """Rows of Table 2, our extra experiments and the baseline with the constraint stage:
    the report's three figures, ``cells(records)`` (ours), the OOD MSE difference to the
    baseline with its p, the report's finding and the verdict."""
    keys = {
        name: c.key
        for c in configs
        for name in [c.points.get(SWEEP_2), *c.aliases.get(SWEEP_2, [])]
        if name is not None
    }
    base = groups.get(keys.get("baseline", ""), [])
    rows = []
    named = [(name, groups.get(key, [])) for name, key in keys.items()]
    for name, mine in [*named, (CONSTRAINED_ROW, constrained(base))]:
        if not mine:
            continue
        if name in REPORT_TABLE2:
            label, *theirs, finding = REPORT_TABLE2[name]
            verdict = _verdict(finding, mine, base, groups, keys)
        else:
            label, theirs, finding, verdict = EXTRA_ROWS.get(name, name), ["–"] * 3, "–", "–"
        rows.append([label, *theirs, *cells(mine), _delta(mine, base, name), finding, verdict])
    return rows


def _delta(mine: list[dict], base: list[dict], name: str) -> str:
    if name == "baseline" or not base:
        return "–"
    if mine is base:
        return "0 (the baseline itself)"
    d, p = difference(mine, base)
    if not math.isfinite(d):
        return f"{'+' if d > 0 else '−'}∞: diverged more (p = {p:.2g})"
    return f"{d:+.3g}" + ("" if math.isnan(p) else f" (p = {p:.2g})")


def _verdict(finding: str, mine, base, groups, keys) -> str:
    if not base:
        return "not comparable: no baseline run"
    if finding == "diverges":
        return diverges(mine, base)
    if finding.startswith("worse"):
        return worse(mine, base)
    return best(groups, {n: keys[n] for n in REPORT_TABLE2 if n in keys})
