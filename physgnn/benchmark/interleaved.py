"""Learned steps against pybullet on the same frames, taking turns: a speed ratio that survives
a busy machine.

For each configuration and size of ``cfg.interleaved``, ``rounds`` rounds each time the
learned simulator over the frames of the size's pybullet run (one step per frame, from the
same states), then pybullet over the same frames from the same start (``engine.substeps``; the
set-up subtracted, :func:`~physgnn.benchmark.scenes.timed_pybullet`). A busy spell of the
machine slows the two halves of a round alike, so each round's ratio (learned FPS over
pybullet's) is kept and their median reported, with the 1-minute load average at the start
and at the end of the rounds.
"""

from __future__ import annotations

import os
import time
from statistics import median

import torch
from omegaconf import DictConfig, OmegaConf

from physgnn.benchmark.learned import frame_states, step_once
from physgnn.benchmark.scenes import timed_pybullet
from physgnn.report.format import md_table


@torch.inference_mode()
def learned_fps(sim, states: list) -> float:
    """Frames per second of one learned step on each of ``states`` in turn (wall clock)."""
    t0 = time.perf_counter()
    for state in states:
        step_once(sim, state)
    return len(states) / (time.perf_counter() - t0)


def taking_turns(sim, states: list, start, engine: dict, rounds: int) -> dict:
    """``rounds`` rounds of the learned steps then pybullet: the FPS of each, each round's
    ratio, their medians and the 1-minute load average before and after."""
    step_once(sim, states[0])  # warm-up (a compiled simulator compiles here)
    load_start = os.getloadavg()[0]
    learned, engine_fps = [], []
    for _ in range(rounds):
        learned.append(learned_fps(sim, states))
        engine_fps.append(timed_pybullet(start, engine)[1])
    ratios = [a / b for a, b in zip(learned, engine_fps, strict=True)]
    return {
        "learned_fps": learned,
        "pybullet_fps": engine_fps,
        "ratios": ratios,
        "median_ratio": median(ratios),
        "loadavg_start": load_start,
        "loadavg_end": os.getloadavg()[0],
    }


def interleaved_rows(cfg: DictConfig, runs: dict, sims: dict) -> list[dict]:
    """Each configuration of ``cfg.interleaved.configs`` (a name of ``sims``,
    :func:`~physgnn.benchmark.learned.build_simulators`) at each size of
    ``cfg.interleaved.sizes`` (``runs[n]``: the pybullet run of that size)."""
    engine = OmegaConf.to_container(cfg.engine)
    rows = []
    for name in cfg.interleaved.configs:
        sim = sims[name][0]
        for n in cfg.interleaved.sizes:
            states = frame_states(runs[n]["traj"], sim.H)
            turns = taking_turns(sim, states, runs[n]["start"], engine, int(cfg.interleaved.rounds))
            rows.append(
                {
                    "config": name,
                    "n_spheres": n,
                    "substeps": int(engine["substeps"]),
                    "frames": len(states),
                    **turns,
                }
            )
            print(
                f"interleaved {name:9s} n={n:6d}: median ratio {turns['median_ratio']:.2f} "
                f"over {len(turns['ratios'])} rounds (load {turns['loadavg_start']:.1f} -> "
                f"{turns['loadavg_end']:.1f})",
                flush=True,
            )
    return rows


def interleaved_table(result: dict) -> str:
    """Learned against pybullet on the same frames, round by round (:mod:`.interleaved`)."""
    body = [
        [
            r["config"],
            str(r["n_spheres"]),
            str(r["substeps"]),
            str(len(r["ratios"])),
            ", ".join(f"{x:.2f}" for x in r["ratios"]),
            f"**{r['median_ratio']:.2f}×**",
            f"{median(r['learned_fps']):.1f}",
            f"{median(r['pybullet_fps']):.1f}",
            f"{r['loadavg_start']:.1f} → {r['loadavg_end']:.1f}",
        ]
        for r in result.get("interleaved", [])
    ]
    header = [
        "config",
        "spheres",
        "pybullet substeps",
        "rounds",
        "ratio per round",
        "median ratio",
        "learned FPS (median)",
        "pybullet FPS (median)",
        "1-min load average",
    ]
    return md_table(header, body)


def interleaved_section(result: dict) -> list[str]:
    return [
        "## Learned against pybullet, taking turns",
        "The learned configurations (their weights: the learned table's) and pybullet on the "
        "same frames of the "
        "same scene in motion, in interleaved rounds (learned, pybullet, learned, …): a busy "
        "spell slows both halves of a round, so each round's ratio of learned FPS to "
        "pybullet's is kept and the targets judge their median; the load average shows how "
        "busy the machine was.",
        interleaved_table(result),
    ]
