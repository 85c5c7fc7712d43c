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


def _ok(met: bool) -> str:
    return "met" if met else "not met"


def targets(result: dict, extra: dict, n_ref: int = 154) -> list[list[str]]:
    """``[target, measured, met]`` rows of the speed targets (baseline configuration)."""
    base = sorted(
        (r for r in extra["learned"] if r["config"] == BASELINE), key=lambda r: r["n_spheres"]
    )
    ref = _row(extra, n_ref) or (base[0] if base else None)
    if ref is None:
        return [["baseline not measured", "–", "–"]]
    return [_fps(ref), _share(ref, base), _graph(ref, base), _linear(base), _pybullet(result, base)]


def _fps(ref: dict) -> list[str]:
    return [
        f"≥ {TARGET_FPS:.0f} FPS at {ref['n_spheres']} spheres",
        f"{ref['fps']:.1f} FPS" + _short(TARGET_FPS / ref["fps"]),
        _ok(ref["fps"] >= TARGET_FPS),
    ]


def _share(ref: dict, base: list[dict]) -> list[str]:
    shares = ", ".join(f"{r['n_spheres']}: {r['share_of_matmul']:.0%}" for r in base)
    return [
        f"network ≥ {TARGET_SHARE:.0%} of the matmul rate",
        shares,
        _ok(ref["share_of_matmul"] >= TARGET_SHARE)
        + f" (at {ref['n_spheres']})"
        + _short(TARGET_SHARE / max(ref["share_of_matmul"], 1e-9)),
    ]


def _graph(ref: dict, base: list[dict]) -> list[str]:
    n = ref["n_spheres"]
    graph = ", ".join(f"{r['n_spheres']}: {r['graph_ms'] / r['total_ms']:.0%}" for r in base)
    met = all(r["graph_ms"] <= TARGET_GRAPH * r["total_ms"] for r in base if r["n_spheres"] >= n)
    return [f"graph ≤ {TARGET_GRAPH:.0%} of a frame (judged from {n} spheres up)", graph, _ok(met)]


def _linear(base: list[dict]) -> list[str]:
    per = {r["n_spheres"]: r["total_ms"] / r["n_spheres"] for r in base}
    big = [k for k in per if k >= 1000] or list(per)
    lo, hi = min(big), max(big)
    ratio = per[hi] / per[lo]
    return [
        f"cost ~ linear: (ms/sphere at {hi}) / (ms/sphere at {lo}) ≤ {TARGET_LINEAR}",
        f"{ratio:.2f}",
        _ok(ratio <= TARGET_LINEAR),
    ]


def _pybullet(result: dict, base: list[dict]) -> list[str]:
    pyb = {r["n_spheres"]: r["fps"] for r in result["pybullet"] if r["substeps"] == 10}
    big = [r for r in base if r["n_spheres"] >= 300 and r["n_spheres"] in pyb]
    text = ", ".join(f"{r['n_spheres']}: {r['fps']:.1f} vs {pyb[r['n_spheres']]:.1f}" for r in big)
    return [
        "≥ pybullet FPS (10 substeps) from 300 spheres up",
        text or "–",
        _ok(bool(big) and all(r["fps"] >= pyb[r["n_spheres"]] for r in big)),
    ]
