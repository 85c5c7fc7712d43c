"""The speed targets of the baseline configuration, met or not, from a bench run."""

from __future__ import annotations

BASELINE = "baseline"
TARGET_FPS, TARGET_SHARE, TARGET_GRAPH, TARGET_LINEAR = 250.0, 0.60, 0.25, 1.5


def _row(extra: dict, n: int) -> dict | None:
    rows = [r for r in extra["learned"] if r["config"] == BASELINE and r["n_spheres"] == n]
    return rows[0] if rows else None


def _short(factor: float) -> str:
    """ " (needs ×k)" when a measured value is ``factor`` short of its target (> 1)."""
    return f" (needs ×{factor:.1f})" if factor > 1 else ""


def targets(result: dict, extra: dict, n_ref: int = 154) -> list[list[str]]:
    """``[target, measured, met]`` rows of the speed targets (baseline configuration)."""
    rows = []
    base = sorted(
        (r for r in extra["learned"] if r["config"] == BASELINE), key=lambda r: r["n_spheres"]
    )
    ref = _row(extra, n_ref) or (base[0] if base else None)
    if ref is None:
        return [["baseline not measured", "–", "–"]]
    n = ref["n_spheres"]
    ok = lambda b: "met" if b else "not met"  # noqa: E731
    rows.append(
        [
            f"≥ {TARGET_FPS:.0f} FPS at {n} spheres",
            f"{ref['fps']:.1f} FPS" + _short(TARGET_FPS / ref["fps"]),
            ok(ref["fps"] >= TARGET_FPS),
        ]
    )
    shares = ", ".join(f"{r['n_spheres']}: {r['share_of_matmul']:.0%}" for r in base)
    rows.append(
        [
            f"network ≥ {TARGET_SHARE:.0%} of the matmul rate",
            shares,
            ok(ref["share_of_matmul"] >= TARGET_SHARE)
            + f" (at {n})"
            + _short(TARGET_SHARE / max(ref["share_of_matmul"], 1e-9)),
        ]
    )
    graph = ", ".join(f"{r['n_spheres']}: {r['graph_ms'] / r['total_ms']:.0%}" for r in base)
    rows.append(
        [
            f"graph ≤ {TARGET_GRAPH:.0%} of a frame (judged from {n} spheres up)",
            graph,
            ok(
                all(
                    r["graph_ms"] <= TARGET_GRAPH * r["total_ms"]
                    for r in base
                    if r["n_spheres"] >= n
                )
            ),
        ]
    )
    per = {r["n_spheres"]: r["total_ms"] / r["n_spheres"] for r in base}
    big = [k for k in per if k >= 1000] or list(per)
    lo, hi = min(big), max(big)
    ratio = per[hi] / per[lo]
    rows.append(
        [
            f"cost ~ linear: (ms/sphere at {hi}) / (ms/sphere at {lo}) ≤ {TARGET_LINEAR}",
            f"{ratio:.2f}",
            ok(ratio <= TARGET_LINEAR),
        ]
    )
    pyb = {r["n_spheres"]: r["fps"] for r in result["pybullet"] if r["substeps"] == 10}
    big = [r for r in base if r["n_spheres"] >= 300 and r["n_spheres"] in pyb]
    text = ", ".join(f"{r['n_spheres']}: {r['fps']:.1f} vs {pyb[r['n_spheres']]:.1f}" for r in big)
    rows.append(
        [
            "≥ pybullet FPS (10 substeps) from 300 spheres up",
            text or "–",
            ok(bool(big) and all(r["fps"] >= pyb[r["n_spheres"]] for r in big)),
        ]
    )
    return rows
