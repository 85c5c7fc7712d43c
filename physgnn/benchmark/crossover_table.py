"""bench.md's crossover section (:mod:`.crossover`): per window, the headline (from which size
the learned simulator is on the MSE20 front), which learned setting is on the front at which
sizes, and one row per size and point with the median and spread over the draws."""

from __future__ import annotations

from physgnn.benchmark.crossover_summary import learned_on_front
from physgnn.report.format import fmt, md_table

TITLE = "## Crossover: the trained model against pybullet on the same work"


def headline(cross: dict, window: str) -> str:
    """One sentence: from which size the reference learned setting is on the MSE20 front of
    ``window``."""
    cases = [c for c in cross["cases"] if c["window"] == window]
    sizes = ", ".join(str(c["n_spheres"]) for c in cases)
    reference = cases[0]["points"][0]["simulator"] if cases else "learned"
    start = cross["front_from"].get(window)
    who = f"The learned simulator ({cross['run']}, {reference})"
    if start is None:
        return f"{window}: {who} is not on the MSE20 front at the largest size (sizes: {sizes})."
    return f"{window}: {who} is on the MSE20 front from **{start} spheres** up (sizes: {sizes})."


def fronts_line(cross: dict, window: str) -> str:
    """Which learned settings are on the front of ``window`` at which sizes."""
    on = learned_on_front([c for c in cross["cases"] if c["window"] == window])
    if not on:
        return f"{window}: no learned setting is on the front at any size."
    parts = [f"{name} at {', '.join(map(str, sizes))}" for name, sizes in on.items()]
    return f"{window}: learned settings on the front: {'; '.join(parts)}."


def _ranged(point: dict, key: str, spec: str = "") -> str:
    """``median (min–max)`` of ``key`` (``fmt`` without ``spec``)."""
    if point[key] is None:
        return "–"
    show = (lambda x: f"{x:{spec}}") if spec else fmt
    mid, low, high = point[key], point[f"{key}_min"], point[f"{key}_max"]
    return f"{show(mid)} ({show(low)}–{show(high)})"


def _note(case: dict, point: dict) -> str:
    on = "on the front" if point["simulator"] in case["front"] else ""
    is_matched = point["substeps"] is not None and point["substeps"] == case["matched_substeps"]
    matched = "matched" if is_matched else ""
    return ", ".join(x for x in (on, matched) if x)


def _knobs(cross: dict, point: dict) -> str:
    if point["setting"] is None:
        return f"{point['substeps']} substeps"
    k = cross["settings"][point["setting"]]
    steps = "compiled" if k["compile"] else "eager"
    return (
        f"passes {k['contact_passes']}, constraints {k['constraints']}, {steps}, "
        f"{k['threads']} thread{'s' if k['threads'] > 1 else ''}"
    )


def crossover_rows(cross: dict) -> list[list[str]]:
    body = []
    for case in cross["cases"]:
        for point in case["points"]:
            body.append(
                [
                    case["window"],
                    str(case["n_spheres"]),
                    point["simulator"],
                    _knobs(cross, point),
                    _ranged(point, "mse20"),
                    _ranged(point, "fps", ".1f"),
                    _ranged(point, "ratio", ".2f"),
                    fmt(point["chamfer"]),
                    fmt(point["depth_sphere"]),
                    str(point["diverged"]),
                    _note(case, point),
                    f"{case['loadavg_start']:.1f} → {case['loadavg_end']:.1f}",
                ]
            )
    return body


HEADER = [
    "window",
    "spheres",
    "simulator",
    "settings",
    "MSE20: median (min–max)",
    "FPS: median (min–max)",
    "first learned FPS / this FPS (median of rounds)",
    "Chamfer",
    "depth sphere",
    "draws diverged",
    "",
    "1-min load average",
]


def section(result: dict) -> list[str]:
    """bench.md's crossover section: per window its headline and the learned settings on the
    front; one row per window, size and point."""
    cross = result.get("crossover")
    if not cross:
        return [TITLE, "Not run (crossover: null)."]
    windows = list(cross["front_from"])
    return [
        TITLE,
        f"Random_box piles, {cross['draws']} draws per size, each cut into windows: "
        f"{', '.join(windows)} (frames after the drop: the crossover's `windows`). Every "
        "simulator starts from the same state (the first H+1 truth frames), is scored against "
        "the truth at the datasets' engine settings and timed one window at a time in "
        "interleaved rounds; each point is the median over the draws, with its range. The "
        "learned settings are the trained model's own knobs; the front is drawn over them and "
        "pybullet's substep counts. matched: the fastest pybullet setting at least as accurate "
        "as the first learned setting at 20 frames (the speed targets' reference).",
        *[headline(cross, w) for w in windows],
        *[fronts_line(cross, w) for w in windows],
        md_table(HEADER, crossover_rows(cross)),
    ]
