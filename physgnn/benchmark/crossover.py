"""The crossover: the trained learned simulator, at each of its settings, against pybullet at
each of its substep counts on the same work, on piles of growing size.

Per size of ``cfg.crossover.sizes`` and per draw (``draws`` random_box piles, one after the
other from the bench's generator): one pile simulated at the truth's settings
(``crossover.engine``: null, the datasets' own); each window of ``crossover.windows`` (its
name: the frame after the drop where it starts: 0 in motion, 30 landed) is the
truth's ``H + 1 + frames`` frames from there. Every learned setting of
``crossover.learned_settings`` (the model's own knobs: contact passes, the constraint stage,
compiled or eager, torch threads; :func:`learned_settings`) rolls out from the window's
first H+1 frames, pybullet at each of ``crossover.substeps`` restarts from frame H; all are
scored with MSE20 (and Chamfer, penetration) against the window. Timing takes turns:
``rounds`` rounds of (every learned setting, every pybullet setting), one window at a time;
each round's ratio of the first learned setting's FPS to each pybullet setting's is kept and
their median taken. Over the draws each point is summarised by its median and spread
(:mod:`.crossover_summary`), and the front and the matched setting judged on the medians.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from statistics import median

from omegaconf import DictConfig, OmegaConf

from physgnn import metrics
from physgnn.benchmark.crossover_summary import front_from, judged, summary
from physgnn.benchmark.scenes import bench_scene, timed_pybullet
from physgnn.benchmark.source import BenchError, Source
from physgnn.groundtruth.engine import simulate
from physgnn.models.settings import check_knobs, torch_threads, with_knobs
from physgnn.physics.trajectory import FRAME_KEYS, continued, scene_at
from physgnn.rollout import rollout

KEYS = ("mse20", "chamfer", "depth_sphere", "depth_ground")


@dataclass
class LearnedSetting:
    """One learned point: its name, simulator and knobs (every one of
    :data:`~physgnn.models.settings.KNOBS`)."""

    name: str
    sim: object
    knobs: dict


def learned_settings(c: DictConfig, source: Source, threads: int) -> list[LearnedSetting]:
    """Each setting of ``c.learned_settings`` (``c``: the ``crossover`` config): the trained
    model of ``source`` with its knobs set, each its own copy
    (:func:`physgnn.models.settings.with_knobs`; absent knobs: eager, ``threads``)."""
    settings = []
    for name, knobs in c.learned_settings.items():
        checked = check_knobs(f"crossover.learned_settings.{name}", knobs, BenchError)
        sim, used = with_knobs(source.simulator(), checked, threads)
        settings.append(LearnedSetting(str(name), sim, used))
    return settings


def as_loaded(name: str, sim, threads: int) -> LearnedSetting:
    """``sim`` as it is (its own contact passes, eager, no constraint stage) at ``threads``
    torch threads (the scripts' runs side by side)."""
    passes = int(sim.contacts.contact_passes)
    knobs = {"contact_passes": passes, "constraints": 0, "compile": False, "threads": threads}
    return LearnedSetting(name, sim, knobs)


def truth_windows(cfg: DictConfig, n: int, rng, H: int, engine: dict) -> dict:
    """One draw of ``n`` spheres: a bench pile simulated once, cut into each window of
    ``crossover.windows`` (name → first frame after the drop), ``H + 1 + frames`` frames."""
    c = cfg.crossover
    starts = {str(name): int(first) for name, first in c.windows.items()}
    length = H + 1 + int(c.frames)
    total = max(starts.values()) + length
    truth = simulate(bench_scene(cfg.scene, n, rng, cfg.area_per_sphere, cfg.h_max, total), engine)
    return {
        name: dataclasses.replace(
            truth, **{k: getattr(truth, k)[first : first + length] for k in FRAME_KEYS}
        )
        for name, first in starts.items()
    }


def _scores(pred, truth) -> dict:
    m = metrics.trajectory_metrics(pred, truth, horizon=20)
    return {k: m.get(k) for k in KEYS}


def taking_turns(
    settings: list[LearnedSetting], window, engine: dict, substeps: list[int], rounds: int
) -> list[dict]:
    """``rounds`` rounds of every learned setting's rollout then pybullet at each substep
    count, from the same start; one row per point: its scores (first round; every point is
    deterministic), median FPS, and for pybullet the median of the rounds' ratios of the first
    learned setting's FPS to its."""
    H = int(settings[0].sim.H)
    for s in settings:  # warm-up (a compiled setting compiles here)
        with torch_threads(s.knobs["threads"]):
            rollout(s.sim, [window.truncated(H + 3)])
    fps = {s.name: [] for s in settings} | {k: [] for k in substeps}
    preds = {}
    for _ in range(rounds):
        for s in settings:
            with torch_threads(s.knobs["threads"]):
                pred = rollout(s.sim, [window])[0]
            fps[s.name].append(pred.fps)
            preds.setdefault(s.name, pred)
        for k in substeps:
            run, rate = timed_pybullet(scene_at(window, H), {**engine, "substeps": k})
            fps[k].append(rate)
            preds.setdefault(k, continued(window, run, H, rate))
    rows = [
        {
            "simulator": f"learned {s.name}",
            "setting": s.name,
            "substeps": None,
            "fps": median(fps[s.name]),
            "ratio": None,
            "diverged_at": preds[s.name].diverged_at,
            **_scores(preds[s.name], window),
        }
        for s in settings
    ]
    reference = fps[settings[0].name]
    for k in substeps:
        rows.append(
            {
                "simulator": f"pybullet-{k}",
                "setting": None,
                "substeps": k,
                "fps": median(fps[k]),
                "ratio": median(a / b for a, b in zip(reference, fps[k], strict=True)),
                "diverged_at": None,
                **_scores(preds[k], window),
            }
        )
    return rows


def measured_size(cfg: DictConfig, settings: list, n: int, rng, engine: dict) -> list[dict]:
    """Every window of ``n`` spheres over ``crossover.draws`` draws: ``{window, n_spheres,
    draws (each draw's rows), points (:func:`summary`), front, on_front, matched_substeps,
    matched_ratio, loadavg_start, loadavg_end}``."""
    c = cfg.crossover
    load = os.getloadavg()[0]
    draws = {str(name): [] for name in c.windows}
    for _ in range(int(c.draws)):
        windows = truth_windows(cfg, n, rng, int(settings[0].sim.H), engine)
        for name, window in windows.items():
            rows = taking_turns(settings, window, engine, list(c.substeps), int(c.rounds))
            draws[name].append(rows)
    cases = []
    for name, rows in draws.items():
        points = summary(rows)
        cases.append(
            {"window": name, "n_spheres": n, "draws": rows, "points": points, **judged(points)}
        )
    end = os.getloadavg()[0]
    return [{**case, "loadavg_start": load, "loadavg_end": end} for case in cases]


def crossover(cfg: DictConfig, rng, source: Source) -> dict | None:
    """Every size and window of ``cfg.crossover`` (None with ``crossover: null``): ``{"run",
    "draws", "settings" (each learned setting's knobs), "cases": [:func:`measured_size`'s],
    "front_from" (per window)}``."""
    c = cfg.get("crossover")
    if c is None:
        return None
    settings = learned_settings(c, source, int(cfg.threads))
    engine = OmegaConf.to_container(c.engine) if c.get("engine") else {}
    cases = []
    for n in c.sizes:
        for case in measured_size(cfg, settings, int(n), rng, engine):
            cases.append(case)
            learned = case["points"][0]
            print(
                f"crossover n={n:6d} {case['window']}: {learned['simulator']} MSE20 "
                f"{learned['mse20']} (median of {c.draws}), front: {', '.join(case['front'])}; "
                f"matched: {case['matched_substeps']}",
                flush=True,
            )
    windows = [str(name) for name in c.windows]
    return {
        "run": source.label,
        "draws": int(c.draws),
        "settings": {s.name: s.knobs for s in settings},
        "cases": cases,
        "front_from": {w: front_from([x for x in cases if x["window"] == w]) for w in windows},
    }
