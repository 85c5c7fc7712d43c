"""The crossover's points over its draws (median and spread), judged on the medians: the
MSE20-against-FPS front over the learned settings and pybullet's substep counts, whether the
reference learned setting (the first) is on it, the matched setting (the fastest pybullet
setting at least as accurate) and from which size the learned simulator stays on the front.
"""

from __future__ import annotations

from statistics import median

from physgnn.report.same_work import pareto_frontier

# summarised by median and spread (min, max) over the draws; the other scores by median
SPREAD = ("mse20", "fps", "ratio")
MEDIAN = ("chamfer", "depth_sphere", "depth_ground")


def spread(values: list) -> tuple[float | None, float | None, float | None]:
    """``(median, min, max)`` of the values that are not None (all None: ``(None,) * 3``)."""
    known = [v for v in values if v is not None]
    if not known:
        return None, None, None
    return median(known), min(known), max(known)


def summary(draws: list[list[dict]]) -> list[dict]:
    """One point per simulator of the draws' rows (each draw: the same simulators in the same
    order, :func:`physgnn.benchmark.crossover.taking_turns`): ``simulator, setting, substeps``,
    the median, ``_min`` and ``_max`` of :data:`SPREAD`, the median of :data:`MEDIAN`, and
    ``diverged``: the draws whose rollout diverged."""
    points = []
    for rows in zip(*draws, strict=True):
        point = {k: rows[0][k] for k in ("simulator", "setting", "substeps")}
        for key in SPREAD:
            mid, low, high = spread([r[key] for r in rows])
            point |= {key: mid, f"{key}_min": low, f"{key}_max": high}
        point |= {key: spread([r[key] for r in rows])[0] for key in MEDIAN}
        point["diverged"] = sum(r["diverged_at"] is not None for r in rows)
        points.append(point)
    return points


def judged(points: list[dict]) -> dict:
    """Of one size's points (learned settings first, the reference first of all): ``front``,
    the points on the MSE20 front (medians; a learned setting that diverged in a draw is left
    out), ``on_front``: whether the reference is, and the matched setting, the fastest pybullet
    at least as accurate as the reference, with the reference's median ratio to it (None where
    none is or the reference diverged)."""
    usable = [p for p in points if p["mse20"] is not None and not p["diverged"]]
    costs = [1.0 / p["fps"] for p in usable]
    front = [usable[i]["simulator"] for i in pareto_frontier(costs, [p["mse20"] for p in usable])]
    reference = points[0]
    ok = reference["mse20"] is not None and not reference["diverged"]
    matched = [
        p for p in usable if ok and p["substeps"] is not None and p["mse20"] <= reference["mse20"]
    ]
    best = max(matched, key=lambda p: p["fps"], default=None)
    return {
        "front": front,
        "on_front": reference["simulator"] in front,
        "matched_substeps": best and best["substeps"],
        "matched_ratio": best and best["ratio"],
    }


def front_from(cases: list[dict]) -> int | None:
    """The smallest size from which the reference learned setting is on the front at every
    larger size measured (``cases``: one window's; None: not at the largest)."""
    start = None
    for case in sorted(cases, key=lambda s: s["n_spheres"], reverse=True):
        if not case["on_front"]:
            break
        start = case["n_spheres"]
    return start


def learned_on_front(cases: list[dict]) -> dict[str, list[int]]:
    """Each learned setting on the front of one window's ``cases``: the sizes where it is."""
    sizes: dict[str, list[int]] = {}
    for case in sorted(cases, key=lambda s: s["n_spheres"]):
        for point in case["points"]:
            if point["setting"] is not None and point["simulator"] in case["front"]:
                sizes.setdefault(point["setting"], []).append(case["n_spheres"])
    return sizes
