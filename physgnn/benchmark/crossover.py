"""The crossover: a trained learned simulator against pybullet on the same work, on piles in
motion of growing size.

Per size of ``cfg.crossover.sizes``: a random_box pile simulated at the truth's settings
(``crossover.engine``: null, the datasets' own) for ``land_frames`` frames, the spheres
landed; then the window of the next ``H + 1 + frames`` frames is the truth. The learned
simulator rolls out from its first H+1 frames, pybullet at each of ``crossover.substeps``
restarts from frame H; both are scored with MSE20 (and Chamfer, penetration) against the
window. Timing takes turns, ``rounds`` rounds of (learned rollout, pybullet at every substep
count), one scene at a time: each round's ratio of learned FPS to each setting's is kept and
their median reported with the load average. The learned simulator is on the front at a size
when no pybullet setting is both as fast and as accurate (MSE20); the crossover is the
smallest size from which it stays on the front; the matched setting of a size is the cheapest
pybullet setting at least as accurate as the learned simulator, the speed targets' reference.
"""

from __future__ import annotations

import dataclasses
import os
from statistics import median

from omegaconf import DictConfig, OmegaConf

from physgnn import metrics
from physgnn.benchmark.learned import make_simulator
from physgnn.benchmark.scenes import bench_scene, timed_pybullet
from physgnn.groundtruth.engine import simulate
from physgnn.physics.trajectory import FRAME_KEYS, continued, scene_at
from physgnn.report.format import fmt, md_table
from physgnn.report.same_work import pareto_frontier
from physgnn.rollout import rollout
from physgnn.training.runs import load_run

KEYS = ("mse20", "chamfer", "depth_sphere", "depth_ground")


def learned_model(cfg: DictConfig, stats: dict):
    """The trained model of ``crossover.run`` (a run folder or ``pretrained``); null: the
    bench's baseline with random weights (tests: the cost is right, the accuracy is not)."""
    if cfg.crossover.run is None:
        return make_simulator(cfg.model, {}, stats)
    sim, _, _ = load_run(str(cfg.crossover.run))
    return sim.eval()


def landed_window(cfg: DictConfig, n: int, rng, H: int, engine: dict):
    """The truth of ``n`` spheres: a bench pile simulated for ``land_frames`` frames (not
    kept), then its next ``H + 1 + frames`` frames."""
    c = cfg.crossover
    total = int(c.land_frames) + H + 1 + int(c.frames)
    scene = bench_scene(cfg.scene, n, rng, cfg.area_per_sphere, cfg.h_max, total)
    truth = simulate(scene, engine)
    cut = int(c.land_frames)
    return dataclasses.replace(truth, **{k: getattr(truth, k)[cut:] for k in FRAME_KEYS})


def _scores(pred, truth) -> dict:
    m = metrics.trajectory_metrics(pred, truth, horizon=20)
    return {k: m.get(k) for k in KEYS}


def taking_turns(sim, window, engine: dict, substeps: list[int], rounds: int) -> list[dict]:
    """``rounds`` rounds of the learned rollout then pybullet at each substep count, from the
    same start; one row per simulator: its scores (first round; both are deterministic),
    median FPS, and for pybullet the median of the rounds' learned-over-pybullet ratios."""
    H = int(sim.H)
    rollout(sim, [window.truncated(H + 3)])  # warm-up
    learned, engine_fps, preds = [], {k: [] for k in substeps}, {}
    for _ in range(rounds):
        pred = rollout(sim, [window])[0]
        learned.append(pred.fps)
        preds.setdefault("learned", pred)
        for k in substeps:
            run, fps = timed_pybullet(scene_at(window, H), {**engine, "substeps": k})
            engine_fps[k].append(fps)
            if k not in preds:
                preds[k] = continued(window, run, H, fps)
    first = preds["learned"]
    rows = [
        {
            "simulator": "learned",
            "substeps": None,
            "fps": median(learned),
            "ratio": None,
            "diverged_at": first.diverged_at,
            **_scores(first, window),
        }
    ]
    for k in substeps:
        ratio = median(a / b for a, b in zip(learned, engine_fps[k], strict=True))
        rows.append(
            {
                "simulator": f"pybullet-{k}",
                "substeps": k,
                "fps": median(engine_fps[k]),
                "ratio": ratio,
                "diverged_at": None,
                **_scores(preds[k], window),
            }
        )
    return rows


def judged(rows: list[dict]) -> dict:
    """Of one size's rows (learned first): whether the learned simulator is on the MSE20 front
    (not diverged), and the matched setting, the fastest pybullet at least as accurate, with
    the learned simulator's median ratio to it (None where none is)."""
    learned, engine = rows[0], rows[1:]
    ok = learned["mse20"] is not None and learned["diverged_at"] is None
    pts = [learned] + engine if ok else engine
    costs = [1.0 / r["fps"] for r in pts]
    errors = [r["mse20"] if r["mse20"] is not None else float("inf") for r in pts]
    on_front = ok and 0 in pareto_frontier(costs, errors)
    matched = [
        r for r in engine if ok and r["mse20"] is not None and r["mse20"] <= learned["mse20"]
    ]
    best = max(matched, key=lambda r: r["fps"], default=None)
    return {
        "on_front": on_front,
        "matched_substeps": best and best["substeps"],
        "matched_ratio": best and best["ratio"],
    }


def front_from(sizes: list[dict]) -> int | None:
    """The smallest size from which the learned simulator is on the front at every larger
    size measured (None: not at the largest)."""
    start = None
    for size in sorted(sizes, key=lambda s: s["n_spheres"], reverse=True):
        if not size["on_front"]:
            break
        start = size["n_spheres"]
    return start


def judged_size(sim, window, n: int, c: DictConfig, engine: dict) -> dict:
    """One size of the crossover: ``sim`` and pybullet take turns on ``window`` (``c``: the
    ``crossover`` config), judged, with the 1-minute load average before and after."""
    load = os.getloadavg()[0]
    rows = taking_turns(sim, window, engine, list(c.substeps), int(c.rounds))
    return {
        "n_spheres": n,
        "rows": rows,
        **judged(rows),
        "loadavg_start": load,
        "loadavg_end": os.getloadavg()[0],
    }


def crossover(cfg: DictConfig, rng, stats: dict) -> dict | None:
    """Every size of ``cfg.crossover`` (None with ``crossover: null``): ``{"run", "sizes":
    [{n_spheres, rows, on_front, matched_substeps, matched_ratio, loadavg_start,
    loadavg_end}], "front_from"}``."""
    c = cfg.get("crossover")
    if c is None:
        return None
    sim = learned_model(cfg, stats)
    engine = OmegaConf.to_container(c.engine) if c.get("engine") else {}
    sizes = []
    for n in c.sizes:
        window = landed_window(cfg, int(n), rng, int(sim.H), engine)
        size = judged_size(sim, window, int(n), c, engine)
        sizes.append(size)
        print(
            f"crossover n={n:6d}: learned MSE20 {size['rows'][0]['mse20']}, on the front: "
            f"{size['on_front']}, matched: {size['matched_substeps']}",
            flush=True,
        )
    run = "random weights" if c.run is None else str(c.run)
    return {"run": run, "sizes": sizes, "front_from": front_from(sizes)}


def headline(cross: dict) -> str:
    """One sentence: from which size the learned simulator is on the MSE20 front."""
    sizes = ", ".join(str(s["n_spheres"]) for s in cross["sizes"])
    if cross["front_from"] is None:
        return (
            f"The learned simulator ({cross['run']}) is not on the MSE20 front at the "
            f"largest size measured (sizes: {sizes})."
        )
    return (
        f"The learned simulator ({cross['run']}) is on the MSE20 front from "
        f"**{cross['front_from']} spheres** up (sizes measured: {sizes})."
    )


def section(result: dict) -> list[str]:
    """bench.md's crossover section: the headline and one row per size and simulator."""
    cross = result.get("crossover")
    if not cross:
        return [
            "## Crossover: the trained model against pybullet on the same work",
            "Not run (crossover: null).",
        ]
    body = []
    for size in cross["sizes"]:
        for r in size["rows"]:
            note = (
                ("on the front" if size["on_front"] else "off the front")
                if r["substeps"] is None
                else ("matched" if r["substeps"] == size["matched_substeps"] else "")
            )
            body.append(
                [
                    str(size["n_spheres"]),
                    r["simulator"],
                    fmt(r["mse20"]),
                    fmt(r["chamfer"]),
                    fmt(r["depth_sphere"]),
                    f"{r['fps']:.1f}",
                    "–" if r["ratio"] is None else f"{r['ratio']:.2f}×",
                    note,
                    f"{size['loadavg_start']:.1f} → {size['loadavg_end']:.1f}",
                ]
            )
    header = [
        "spheres",
        "simulator",
        "MSE20",
        "Chamfer",
        "depth sphere",
        "FPS (median)",
        "learned FPS / this FPS (median of rounds)",
        "",
        "1-min load average",
    ]
    return [
        "## Crossover: the trained model against pybullet on the same work",
        "Piles in motion after the spheres have landed; every simulator from the same start (the "
        "first H+1 truth frames), scored against the truth at the datasets' engine settings, timed "
        "one scene at a time in interleaved rounds. matched: the fastest pybullet setting at "
        "least as accurate as the learned simulator at 20 frames (the speed targets' reference).",
        headline(cross),
        md_table(header, body),
    ]
