"""The speed targets of the baseline configuration, met or not, from a bench run."""

from __future__ import annotations

BASELINE = "baseline"
# FPS of one learned step per sphere count; the network's share of the matmul rate from
# SHARE_FROM spheres up; graph share of a frame; cost linearity; training's FLOP-rate share
# of the matmul rate and its nodes per second (bench scenes).
TARGET_FPS = {154: 400.0, 1000: 120.0}
TARGET_SHARE, SHARE_FROM, TARGET_GRAPH, TARGET_LINEAR = 0.50, 300, 0.25, 1.5
TARGET_TRAIN_SHARE, TARGET_TRAIN_NODES = 0.60, 40_000.0
# learned FPS / the FPS of the fastest pybullet setting at least as accurate (MSE20) on the
# same work, the trained model on landed piles (the crossover's window MATCHED_WINDOW; medians
# over its draws of the interleaved rounds' medians)
MATCHED_RATIO = {154: 2.0, 1000: 5.0}
MATCHED_WINDOW = "landed"


def _row(extra: dict, n: int) -> dict | None:
    rows = [r for r in extra["learned"] if r["config"] == BASELINE and r["n_spheres"] == n]
    return rows[0] if rows else None


def _short(factor: float) -> str:
    """ " (needs ×k)" when a measured value is ``factor`` short of its target (> 1)."""
    if factor <= 1:
        return ""
    return f" (needs ×{factor:.2f})" if factor < 1.1 else f" (needs ×{factor:.1f})"


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
    fps = [_fps(row) for n in TARGET_FPS if (row := _row(extra, n)) is not None]
    rows = fps + [_share(base), _graph(ref, base), _linear(base), _matched(result)]
    return rows + _training(extra.get("training"))


def _fps(row: dict) -> list[str]:
    target = TARGET_FPS[row["n_spheres"]]
    return [
        f"≥ {target:.0f} FPS at {row['n_spheres']} spheres",
        f"{row['fps']:.1f} FPS" + _short(target / row["fps"]),
        _ok(row["fps"] >= target),
    ]


def _share(base: list[dict]) -> list[str]:
    shares = ", ".join(f"{r['n_spheres']}: {r['share_of_matmul']:.0%}" for r in base)
    judged = [r["share_of_matmul"] for r in base if r["n_spheres"] >= SHARE_FROM]
    low = min(judged, default=0.0)
    return [
        f"network ≥ {TARGET_SHARE:.0%} of the matmul rate from {SHARE_FROM} spheres up",
        shares,
        _ok(bool(judged) and low >= TARGET_SHARE) + _short(TARGET_SHARE / max(low, 1e-9)),
    ]


def _training(t: dict | None) -> list[list[str]]:
    """Training throughput: FLOP-rate share of the matmul rate and nodes per second."""
    if not t or "share_of_matmul" not in t:
        return []
    share, nodes = t["share_of_matmul"], t["nodes_per_s"]
    return [
        [
            f"training ≥ {TARGET_TRAIN_SHARE:.0%} of the matmul rate (FLOP rate)",
            f"{share:.0%} ({t['gflops']:.1f} GFLOP/s)",
            _ok(share >= TARGET_TRAIN_SHARE) + _short(TARGET_TRAIN_SHARE / max(share, 1e-9)),
        ],
        [
            f"training ≥ {TARGET_TRAIN_NODES / 1000:.0f} k nodes/s (bench scenes)",
            f"{nodes / 1000:.1f} k nodes/s",
            _ok(nodes >= TARGET_TRAIN_NODES) + _short(TARGET_TRAIN_NODES / max(nodes, 1e-9)),
        ],
    ]


def _graph(ref: dict, base: list[dict]) -> list[str]:
    n = ref["n_spheres"]
    graph = ", ".join(f"{r['n_spheres']}: {r['graph_ms'] / r['total_ms']:.0%}" for r in base)
    met = all(r["graph_ms"] <= TARGET_GRAPH * r["total_ms"] for r in base if r["n_spheres"] >= n)
    return [f"graph ≤ {TARGET_GRAPH:.0%} of a frame (judged from {n} spheres up)", graph, _ok(met)]


def _linear(base: list[dict]) -> list[str]:
    per = {r["n_spheres"]: r["total_ms"] / r["n_spheres"] for r in base}
    big = [k for k in per if k >= 1000]
    big = big if len(big) > 1 else [k for k in per if k >= SHARE_FROM]
    if len(big) < 2:
        return ["cost ~ linear", f"needs two sizes from {SHARE_FROM} spheres", "not judged"]
    lo, hi = min(big), max(big)
    ratio = per[hi] / per[lo]
    return [
        f"cost ~ linear: (ms/sphere at {hi}) / (ms/sphere at {lo}) ≤ {TARGET_LINEAR}",
        f"{ratio:.2f}",
        _ok(ratio <= TARGET_LINEAR),
    ]


def _matched(result: dict) -> list[str]:
    """The first learned setting's FPS over the matched pybullet setting's (the fastest at
    least as accurate at 20 frames, medians over the draws: :mod:`physgnn.benchmark.crossover`),
    the median over the draws of each draw's median of the interleaved rounds, on the
    :data:`MATCHED_WINDOW` window against :data:`MATCHED_RATIO` at each of its sizes the
    crossover measured; a size where no setting tried is as accurate is not judged (not met)."""
    cases = [
        c
        for c in (result.get("crossover") or {}).get("cases", [])
        if c["window"] == MATCHED_WINDOW and c["n_spheres"] in MATCHED_RATIO
    ]
    texts = [
        f"{c['n_spheres']}: no setting tried is as accurate"
        if c["matched_substeps"] is None
        else f"{c['n_spheres']}: {c['matched_ratio']:.2f}× against {c['matched_substeps']} "
        f"substeps (load {c['loadavg_start']:.1f})"
        for c in cases
    ]
    met = bool(cases) and all(
        c["matched_ratio"] is not None and c["matched_ratio"] >= MATCHED_RATIO[c["n_spheres"]]
        for c in cases
    )
    wanted = ", ".join(f"≥ {k:g}× at {n}" for n, k in MATCHED_RATIO.items())
    return [
        "learned FPS over the fastest pybullet setting at least as accurate (MSE20; the trained "
        f"model on {MATCHED_WINDOW} piles, medians over the draws of the interleaved rounds' "
        f"medians): {wanted} spheres",
        "; ".join(texts) or "–",
        _ok(met),
    ]
