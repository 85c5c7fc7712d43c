"""The study report's Sweeps section: per sweep its figure and the validation rollouts against
the step (``sweep_<name>.png``, ``curve_<name>.png``), the energy term's share of the loss per λ,
and the rollout FPS per configuration (``fps.png``)."""

from __future__ import annotations

from pathlib import Path

from physgnn.ablation.aggregate import mean_fps, mean_logged
from physgnn.ablation.figures import plot_study_curves, plot_study_fps, plot_study_sweep

FIGURE_SWEEPS = {  # sweep → (figure title, metrics)
    "ablation_H": ("History H (report Fig. 15)", ["mse", "chamfer", "energy_gain"]),
    "ablation_M": (
        "Message-passing blocks M (report Fig. 16)",
        ["mse", "chamfer", "energy_gain", "depth_sphere"],
    ),
    "ablation_connectivity": ("Connectivity (report Fig. 17)", ["chamfer", "energy_gain"]),
    "ablation_lambda": ("Energy-term weight λ", ["mse", "energy_gain", "energy_share"]),
}
FPS_SWEEPS = ("ablation_H", "ablation_M", "ablation_connectivity")


def sweeps_section(out: Path, groups, configs) -> str:
    """The section's markdown; its figures written into ``out``."""
    lines = ["## Sweeps", ""]
    for sweep, (title, metrics) in FIGURE_SWEEPS.items():
        points = sorted(
            ((c.points[sweep], c) for c in configs if sweep in c.points), key=lambda p: _num(p[0])
        )
        if not points or not any(groups.get(c.key) for _, c in points):
            continue
        name = f"sweep_{sweep.removeprefix('ablation_')}.png"
        plot_study_sweep(
            out / name,
            title,
            [x for x, _ in points],
            [groups.get(c.key, []) for _, c in points],
            metrics,
        )
        lines += [f"![{title}]({name})", ""]
        curves = [(x, groups.get(c.key, [])) for x, c in points]
        if any(r.get("curve") for _, recs in curves for r in recs):
            curve = f"curve_{sweep.removeprefix('ablation_')}.png"
            plot_study_curves(out / curve, f"{title}: validation rollouts during training", curves)
            lines += [f"![{title}: learning curves]({curve})", ""]
        if sweep == "ablation_lambda":
            lines += [_energy_shares(points, groups), ""]
    fps = [
        (f"{s.removeprefix('ablation_')}={c.points[s]}", mean_fps(groups.get(c.key, [])))
        for s in FPS_SWEEPS
        for c in configs
        if s in c.points
    ]
    if any(stat.mean is not None for _, stat in fps):
        note = "per run on its own thread, two runs at a time"
        plot_study_fps(out / "fps.png", [k for k, _ in fps], [s for _, s in fps], note)
        lines += ["![Rollout FPS per configuration](fps.png)", ""]
    return "\n".join(lines)


def _energy_shares(points, groups) -> str:
    """The energy term's share of the loss per λ: as designed, λ × the penalty of the model
    trained without it ÷ that model's loss plus it, and the factor by which training with it cut
    the penalty (last epoch's means over seeds), beside the logged mean of per-batch shares."""
    base = next((groups.get(c.key, []) for x, c in points if _num(x)[1] == 0), [])
    penalty0, loss0 = mean_logged(base, "train/loss_energy"), mean_logged(base, "train/loss")
    parts = []
    for x, config in points:
        recs = groups.get(config.key, [])
        lam, logged = _num(x)[1], mean_logged(recs, "train/energy_share")
        penalty = mean_logged(recs, "train/loss_energy")
        if lam == 0 or penalty0 is None or loss0 is None:
            continue
        designed = lam * penalty0 / (loss0 + lam * penalty0)
        fell = f"{penalty0 / penalty:.3g}×" if penalty else "–"
        shown = f"{100 * logged:.2g} %" if logged is not None else "–"
        parts.append(f"| {x} | {100 * designed:.2g} % | {fell} | {shown} |")
    if not parts:
        return ""
    return "\n".join(
        [
            "The energy term's share of the loss, per λ: *as designed* is λ × the penalty of the "
            "model trained without it (λ = 0) ÷ (its loss + that), the share the term would have "
            "if the model did not learn to avoid it; *penalty cut* is λ = 0's penalty over this "
            "λ's; *logged* the last epoch's mean of per-batch shares (small once the penalty is "
            "cut).",
            "",
            "| λ | share as designed | penalty cut | logged share |",
            "|---|---|---|---|",
            *parts,
        ]
    )


def _num(x: str):
    try:
        return (0, float(x), x)
    except ValueError:
        return (1, 0.0, x)
