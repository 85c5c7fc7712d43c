"""``bench.md``'s training sections: throughput, FLOP rate and the profile of one step."""

from __future__ import annotations

import math

from physgnn.benchmark.profile import PARTS
from physgnn.report.format import fmt_as, md_table


def training_table(extra: dict) -> str:
    t = extra["training"]
    return md_table(
        [
            "pairs/s",
            "nodes/s",
            "batch",
            "nodes per pair",
            "steps timed",
            "GFLOP/s",
            "share of matmul",
        ],
        [
            [
                f"{t['pairs_per_s']:.1f}",
                f"{t['nodes_per_s']:.0f}",
                str(t["batch_size"]),
                f"{t['mean_nodes_per_pair']:.1f}",
                str(t["steps_timed"]),
                f"{t.get('gflops', math.nan):.1f}",
                f"{t.get('share_of_matmul', math.nan):.0%}",
            ]
        ],
    )


def profile_table(extra: dict) -> str:
    """One training step, part by part (``benchmark.profile``)."""
    p = extra.get("profile")
    if not p:
        return "–"
    body = [[k.replace("_", "-"), f"{p[f'{k}_ms']:.2f}", f"{p[f'{k}_share']:.0%}"] for k in PARTS]
    body.append(["whole step", f"{p['step_ms']:.2f}", f"{p['pairs_per_s']:.0f} pairs/s"])
    if "gflops" in p:
        rate = f"{p['gflops']:.1f} GFLOP/s, {p['share_of_matmul']:.0%} of matmul"
        body.append(["FLOPs of the step", f"{p['gflop_per_step']:.2f} GFLOP", rate])
    return md_table(["part", "ms per step", "share"], body)


def training_sections(extra: dict) -> list[str]:
    """The training throughput and the profile of one training step, with their titles."""
    return [
        "## Training throughput (baseline, Lightning, noise on)",
        "GFLOP/s: 3 × the dense-layer FLOPs of each batch's forward (forward and backward) "
        "per second; share of matmul: that rate / the best measured matmul rate.",
        training_table(extra),
        "### Where a training step's time goes (baseline, "
        f"{extra.get('profile', {}).get('batch_size', '?')} pairs, noise, "
        f"{extra.get('profile', {}).get('pushforward_steps', '?')} push-forward step)",
        "Graph building counts every graph of the step (push-forward and loss); forward and "
        "push-forward are the network and its normalisation without it; optimiser = gradient "
        "clipping and the Adam step. A rollout frame's parts are in the rollout table above. "
        "FLOPs: the dense layers of every network call, the loss graph's 3 times (forward and "
        "backward), the push-forward graphs' once.",
        profile_table(extra),
    ]


def gpu_readiness_section(result: dict) -> list[str]:
    """Syncs, kernels and host ms of a training step and a rollout frame, with the title."""
    g = result.get("gpu_readiness")
    if not g:
        return []
    body = [
        [part.replace("_", " "), fmt_as(c["syncs"]), fmt_as(c.get("copies", 0))]
        + [fmt_as(c["kernels"], ".0f"), fmt_as(c["host_ms"])]
        for part, c in g.items()
    ]
    return [
        "## What would make a GPU wait (counted on this machine)",
        "Per training step (the default recipe through Lightning, push-forward drawn each step: "
        "the most of the steps counted) and per rollout frame: host round trips a GPU would "
        "wait for (syncs, of which host-to-device copies), aten ops (about one kernel each) "
        "and host ms with a network of "
        "hidden size 4, torch neighbour backend (physgnn/benchmark/gpu_readiness.py; the "
        "source lines of the syncs are in bench_extra.json). Compiled: the aten ops dispatched "
        "outside the compiled regions of lit.compile.enabled=true (syncs and time not counted "
        "there).",
        md_table(["", "syncs", "copies", "kernels", "host ms"], body),
    ]


def _failed(row: dict, cells: int) -> list[str]:
    """``cells`` cells of a row whose measurement failed: the error, then dashes."""
    return [f"failed: {row['error']}"] + ["–"] * (cells - 1)


def gpu_section(result: dict) -> list[str]:
    """The GPU rows of ``make bench`` (physgnn/benchmark/gpu.py), or the line saying why none."""
    g = result.get("gpu")
    if not g:
        return ["## GPU", "Skipped: torch saw no CUDA device in this run."]
    train = [
        [r["variant"]]
        + (
            _failed(r, 3)
            if "error" in r
            else [
                f"{r['steps_per_s']:.1f}",
                f"{r['nodes_per_s']:.0f}",
                fmt_as(r["peak_mib"], ".0f"),
            ]
        )
        for r in g["training"]
    ]
    frames = [
        [f"{r['n_spheres']}", r.get("variant", "eager")]
        + (_failed(r, 2) if "error" in r else [f"{r['fps']:.1f}", fmt_as(r["peak_mib"], ".0f")])
        for r in g["rollout"]
    ]
    return [
        f"## GPU ({g['device']})",
        "Training of the default recipe at batch "
        f"{g['batch_size']}: optimiser steps and "
        "spheres per second, peak memory (physgnn/benchmark/gpu.py).",
        md_table(["variant", "steps/s", "spheres/s", "peak MiB"], train),
        "Rollout of the baseline (random weights) through physgnn.rollout:",
        md_table(["spheres", "variant", "FPS", "peak MiB"], frames),
    ]
