"""The study page's section on the default model's changes, each switched off alone (the sweep
``ablation_contacts``): which change moves which figure.

Each row is one variant against the baseline *on the seeds both have*: its mean over those
seeds and the paired difference ``variant − baseline`` (seed by seed, then averaged), with the
paired t-test's two-sided p where two or more seeds match. A seed whose rollouts diverged has
no figure (∞); its differences are not averaged but named.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from physgnn.ablation.aggregate import checkpoint_text, seed_value
from physgnn.ablation.jobs import BASELINE, Config
from physgnn.report.format import fmt, md_table

SWEEP = "ablation_contacts"
LABELS = {
    "no_contact_passes": "one pass (no rebuild within the frame)",
    "no_pair_impulses": "without the pair impulses",
    "latch": "with the previous latch",
    "no_truth_contacts": "loss graph without the truth's contacts",
    "no_plane_materials": "without the materials on plane edges",
    "no_contact_features": "without the contact inputs",
    "no_material_features": "without the material inputs",
    "no_gravity_prior": "without the gravity prior",
    "no_contact_penalty": "without the contact penalty",
    "no_contact_noise": "without the contact noise",
    "layer_norm": "with LayerNorm",
    "contact_memory": "with the contact memory",
    "no_pushforward": "push-forward off",
    "pushforward_growing": "push-forward growing from 1 to 4 steps",
}
# (split, metric, column title)
FIGURES = [
    ("ood", "mse", "OOD MSE"),
    ("ood", "max_depth_sphere", "OOD max sphere depth (d)"),
    ("ood", "max_depth_plane", "OOD max plane depth (d)"),
    ("ood", "tunnelled", "OOD tunnelled"),
    ("ood", "energy_error", "OOD energy error"),
    ("test", "mse", "test MSE"),
]


def paired(mine: list[dict], base: list[dict], split: str, metric: str) -> str:
    """``mean (Δ ±x, p = …)`` over the seeds both ``mine`` and ``base`` have (module doc)."""
    by_seed = {r["seed"]: r for r in base}
    pairs = [
        (seed_value(r, split, metric), seed_value(by_seed[r["seed"]], split, metric))
        for r in mine
        if r["seed"] in by_seed
    ]
    pairs = [(a, b) for a, b in pairs if a is not None and b is not None]
    if not pairs:
        return "–"
    gone = sum(not math.isfinite(a) for a, _ in pairs)
    finite = [(a, b) for a, b in pairs if math.isfinite(a) and math.isfinite(b)]
    if not finite:
        return f"∞ ({gone}/{len(pairs)} seeds diverged)"
    a, b = np.array(finite).T
    text = f"{fmt(float(a.mean()))} (Δ {float((a - b).mean()):+.3g}"
    if len(finite) > 1 and np.std(a - b) > 0:
        text += f", p = {float(stats.ttest_rel(a, b).pvalue):.2g}"
    text += ")"
    return text + (f"; ∞ in {gone}/{len(pairs)} seeds" if gone else "")


def _score(records: list[dict]) -> str:
    return checkpoint_text(records, "val_score", at=" @ ")


def switches_section(groups: dict[str, list[dict]], configs: list[Config]) -> str:
    """The section's markdown ('' when no variant of the sweep has a run yet)."""
    base = groups.get(BASELINE, [])
    rows = []
    for config in configs:
        name = config.points.get(SWEEP)
        mine = groups.get(config.key, [])
        if name is None or config.key == BASELINE or not mine or not base:
            continue
        seeds = sorted(r["seed"] for r in mine)
        cells = [paired(mine, base, split, metric) for split, metric, _ in FIGURES]
        rows.append([LABELS.get(name, name), ", ".join(map(str, seeds)), *cells, _score(mine)])
    if not rows:
        return ""
    header = ["change", "seeds", *(title for _, _, title in FIGURES), "checkpoint score @ step"]
    header[-1] += f" (baseline, {len(base)} seeds: {_score(base)})"
    return "\n".join(
        [
            "## The default's contact changes, each switched off alone",
            "",
            "Each row against the baseline on the same seeds: the row's mean over those seeds and "
            "the paired difference Δ = row − baseline (seed by seed; the paired t-test's p where "
            "two or more seeds match). A row that switches a change *off* with Δ > 0 on a depth, "
            "error or tunnelling figure means the change lowers it. The checkpoint score is the "
            "validation rollout score of the checkpoint measured (lower is better; the "
            "push-forward schedule is chosen on it, never on test or OOD).",
            "",
            md_table(header, rows),
        ]
    )
