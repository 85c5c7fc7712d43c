"""frames/s of the same-work table taken in turns, so that a front does not hang on the drift.

An eval rolls out every learned run and setting first and pybullet after them, minutes apart;
on a machine whose speed drifts (another job starts, a shared VM's neighbour gets busy) the
two sides of a row were timed on different machines, and a learned point can land on a front,
or leave it, by the drift alone. So, with scenes batched, each split is timed again in
``turns`` rounds: in each, every learned rollout of the split (each under its own torch
threads) and then pybullet at every substep count (in ``pybullet.processes`` processes), one
right after the other; a row's frames/s is the median over the rounds, as the bench's
crossover takes its (:func:`physgnn.benchmark.crossover.taking_turns`). The scores stay those
of the first rollouts (every rollout is deterministic). ``turns: 0`` keeps the first timings.
"""

from __future__ import annotations

from collections import defaultdict
from statistics import median

from physgnn.evaluation.rollouts import predict_split, progress
from physgnn.evaluation.runs import SPLITS, RunInfo
from physgnn.evaluation.same_work import engine_name, engine_split, seeded
from physgnn.models.settings import torch_threads
from physgnn.ranges import whole

TURNS = whole(0, what="rounds of timing in turns; 0: as first timed", example=1)


def check_turns(pybullet) -> int:
    """``pybullet.turns`` of the eval's ``pybullet`` group: a whole number >= 0 (absent: 0)."""
    return TURNS.check("pybullet.turns", (pybullet or {}).get("turns", 0))


def timed_in_turns(
    learned: list[tuple[RunInfo, int | None]],
    engines: list[RunInfo],
    data: dict,
    plan: tuple[list[int], int, int],
    settings: dict | None = None,
) -> dict[tuple[str, str], float]:
    """``{(row name, split): median frames/s}`` over the rounds (module doc). ``learned``: each
    learned job with its torch threads; ``engines``: the pybullet references
    (:func:`physgnn.evaluation.same_work.engine_jobs`: name suffix, dataset, ``extra["H"]``);
    ``data``: ``{dataset: {split: [Trajectory]}}``; ``plan``: ``(substeps, processes,
    rounds)``; ``settings``: the rollouts' keyword arguments."""
    substeps, processes, rounds = plan
    fps = defaultdict(list)
    with progress() as bar:
        task = bar.add_task("timed in turns", total=len(data) * len(SPLITS) * rounds)
        for dataset, split in ((d, s) for d in data for s in SPLITS):
            trajs = data[dataset][split]
            for turn in range(rounds):
                bar.update(task, description=f"timed in turns · {split} · round {turn + 1}")
                for job, threads in (j for j in learned if j[0].dataset == dataset):
                    with torch_threads(threads):
                        preds = predict_split(job, trajs, settings)
                    fps[job.name, split].append(preds[0].fps if preds else None)
                for engine in (e for e in engines if e.dataset == dataset):
                    for k in substeps:
                        rate = _engine_rate(trajs, engine.extra["H"], k, processes)
                        fps[engine_name(k, engine), split].append(rate)
                bar.advance(task)
    return {key: median(rates) for key, rates in fps.items() if None not in rates}


def _engine_rate(trajs: list, H: int, k: int, processes: int) -> float | None:
    """pybullet's frames/s at ``k`` substeps on the split ``trajs`` from frame ``H`` (None:
    no trajectory long enough)."""
    preds = engine_split(seeded(trajs, H), H, k, processes)
    return preds[0].fps if preds else None


def retimed(rows: list[dict], fps: dict[tuple[str, str], float]) -> list[dict]:
    """``rows`` (metrics.csv's) with the frames/s of every row timed in turns replaced."""
    return [row | {"fps": fps.get((row["run"], row["split"]), row["fps"])} for row in rows]
