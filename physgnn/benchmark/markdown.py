"""``bench.md``: the tables of ``make bench`` and its speed targets (met or not)."""

from __future__ import annotations

import math
import os

from physgnn.benchmark import crossover_table
from physgnn.benchmark.interleaved import interleaved_section
from physgnn.benchmark.targets import targets
from physgnn.benchmark.training_tables import (
    gpu_readiness_section,
    gpu_section,
    training_sections,
)
from physgnn.report.format import fmt, md_table

# pybullet's accuracy-versus-time curve on the bench pile, beside bench.md
ACCURACY_FIGURE = "pybullet_accuracy.png"


def _f(x, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.{digits}g}" if isinstance(x, float) else str(x)


def machine_table(extra: dict) -> str:
    m = extra["machine"]
    start, end = m.get("loadavg_start", math.nan), extra.get("loadavg_end", math.nan)
    load = f"{start:.1f} at start, {end:.1f} at end"
    rates = ", ".join(f"{k}: {v:.1f}" for k, v in m.get("matmul_by_shape", {}).items())
    body = [
        ["CPU", m["cpu"]],
        ["torch threads", str(m["threads"])],
        ["fp32 matmul rate (best, GFLOP/s)", f"{m['matmul_gflops']:.1f}"],
        ["per shape [m×k×n] (GFLOP/s)", rates],
        ["torch", m.get("torch", "?")],
        ["same, first shape on 1 thread (GFLOP/s)", f"{m.get('matmul_gflops_1_thread', 0):.1f}"],
        ["1-min load average (other processes compete for the cores)", load],
        ["OMP_WAIT_POLICY", m.get("omp_wait_policy", "?")],
        [
            "GOMP_SPINCOUNT (spins before an idle OpenMP thread sleeps)",
            m.get("gomp_spincount", "?"),
        ],
    ]
    table = md_table(["machine", ""], body)
    if m["threads"] > 1 and start > os.cpu_count():
        table += (
            f"\n\n⚠ The load average ({start:.1f}) exceeds the {os.cpu_count()} cores: "
            "other processes share them and multi-threaded timings suffer most."
        )
    return table


def learned_table(extra: dict) -> str:
    body = []
    for r in extra["learned"]:
        frame = r["total_ms"]
        body.append(
            [
                r["config"],
                r["weights"],
                str(r["n_spheres"]),
                f"{r['fps']:.1f}",
                f"{frame:.2f}",
                f"{r['graph_ms']:.2f}",
                f"{r['network_ms']:.2f}",
                f"{r['integrate_ms']:.2f}",
                f"{r['graph_ms'] / frame:.0%}",
                f"{1000 * frame / r['n_spheres']:.2f}",
                f"{r['pp_edges']:.0f}",
                f"{r['ps_edges']:.0f}",
                f"{r['gflop_per_step']:.3f}",
                f"{r['share_of_matmul']:.0%}",
            ]
        )
    return md_table(
        [
            "config",
            "weights",
            "spheres",
            "FPS",
            "ms/frame",
            "graph ms",
            "network ms",
            "integrate ms",
            "graph share",
            "µs/sphere",
            "pp edges",
            "ps edges",
            "GFLOP/step",
            "share of matmul",
        ],
        body,
    )


def pybullet_table(result: dict) -> str:
    body = [
        [
            str(r["n_spheres"]),
            str(r["substeps"]),
            f"{r['fps']:.1f}",
            f"{1000 / r['fps']:.2f}",
            fmt(r["mse_vs_reference"]),
        ]
        for r in result["pybullet"]
    ]
    return md_table(["spheres", "substeps", "FPS", "ms/frame", "position MSE vs reference"], body)


def accuracy_table(extra: dict) -> str:
    body = []
    for r in extra["pybullet_accuracy"]:
        name = f"{r['substeps']} (reference)" if r["reference"] else str(r["substeps"])
        body.append(
            [
                name,
                _f(r["fps"]),
                fmt(r.get("mse")),
                fmt(r.get("mse5")),
                fmt(r.get("chamfer")),
                fmt(r["energy_gain"]),
                fmt(r["depth_sphere"]),
                fmt(r["depth_ground"]),
                fmt(r["pct_sphere"]),
                fmt(r.get("free_fall_error")),
            ]
        )
    return md_table(
        [
            "substeps",
            "FPS",
            "MSE (all frames)",
            "MSE at frame 5",
            "Chamfer",
            "energy gain",
            "depth sphere",
            "depth ground",
            "% spheres intersecting",
            "free-fall error after 4 s (m)",
        ],
        body,
    )


def activity_table(extra: dict) -> str:
    body = [
        [
            r["case"],
            str(r["n_spheres"]),
            f"{r['total_ms']:.2f}",
            f"{r['graph_ms']:.2f}",
            f"{r['network_ms']:.2f}",
            f"{r['nodes']:.0f}",
            f"{r['pp_edges']:.0f}",
            f"{r['ps_edges']:.0f}",
        ]
        for r in extra["activity"]
    ]
    return md_table(
        [
            "case",
            "spheres",
            "ms/frame",
            "graph ms",
            "network ms",
            "nodes in network",
            "pp edges",
            "ps edges",
        ],
        body,
    )


def rollout_table(extra: dict) -> str:
    body = [
        [
            str(r["n_spheres"]),
            str(r["frames"]),
            f"{r['fps']:.1f}",
            f"{r['total_ms']:.2f}",
            f"{r['graph_ms']:.2f}",
            f"{r['network_ms']:.2f}",
            f"{r['integration_ms']:.2f}",
            f"{r['total_ms'] - r['graph_ms'] - r['network_ms'] - r['integration_ms']:.2f}",
        ]
        for r in extra.get("rollout", [])
    ]
    head = ["spheres", "frames", "FPS", "ms/frame", "graph ms", "network ms", "integration ms"]
    return md_table([*head, "other ms (recording, scene bookkeeping)"], body)


def batched_table(extra: dict) -> str:
    body = [
        [
            str(r["scenes"]),
            str(r["n_spheres"]),
            f"{r['batch_ms']:.2f}",
            f"{r['ms_per_scene']:.2f}",
            f"{r['scene_fps']:.1f}",
        ]
        for r in extra.get("batched", [])
    ]
    return md_table(
        [
            "scenes in the batch",
            "spheres each",
            "ms per batch step",
            "ms per scene-frame",
            "scene-frames per s",
        ],
        body,
    )


def targets_heading(model: dict) -> str:
    """``## Targets (baseline M=.. H=.. <connectivity> h=..)`` from the learned rows' model
    config (the run's, else the bench's)."""
    net, graph = model.get("network", {}), model.get("graph", {})
    return (
        f"## Targets (baseline M={net.get('M', '?')} H={model.get('H', '?')} "
        f"{graph.get('connectivity', '?')} h={net.get('hidden', '?')})"
    )


def write_markdown(result: dict, extra: dict) -> str:
    """The whole ``bench.md`` text."""
    s = extra.get("settings", {})
    parts = [
        "# physgnn bench: accuracy versus time",
        f"One run of `python -m physgnn.bench` ({result.get('wall_s', 0):.0f} s in all). The "
        f"learned rows run the model of `run` ({result.get('run', '?')}); the configurations "
        "marked random weights (an architecture change, or the baseline with random weights) "
        "cannot run the trained weights. Learned steps are timed one step "
        "per pybullet frame of the same scene in motion (random_box, "
        f"{s.get('area_per_sphere', '?')} m² of floor per sphere, after "
        f"{s.get('warmup_frames', '?')} warm-up frames).",
        "Seconds per phase: "
        + (", ".join(f"{k} {v:.0f}" for k, v in extra.get("phase_s", {}).items()) or "–")
        + ".",
        "## Machine",
        machine_table(extra),
        targets_heading(extra.get("learned_model", s.get("model", {}))),
        md_table(["target", "measured", "status"], targets(result, extra)),
        "## Learned simulator per configuration and size",
        "ms/frame = graph + network (incl. normalisation) + integration; share of matmul = "
        "network FLOP rate / best measured matmul rate.",
        learned_table(extra),
        "### The trained model through `physgnn.rollout`: where a rollout frame's time goes",
        rollout_table(extra),
        "### Batching scenes (baseline, copies of the same scene in one graph)",
        batched_table(extra),
        *crossover_table.section(result),
        *interleaved_section(result),
        "## pybullet frame rate",
        pybullet_table(result),
        "## pybullet: substeps versus accuracy",
        f"From the same state in motion, {s.get('accuracy', {}).get('frames', '?')} frames; "
        "reference: the most substeps. Physics metrics are of each run itself; free-fall error: "
        "|z − (z0 − ½gt²)| of one sphere after 4 s (semi-implicit Euler lags by g·h·t/2). "
        "This is the engine's own curve on the bench pile, a different work from the eval's "
        "scenes: the eval's Pareto view compares the learned runs with pybullet on their own "
        "test and OOD scenes (report.md).",
        accuracy_table(extra),
        f"![pybullet accuracy versus time on the bench pile]({ACCURACY_FIGURE})",
        *training_sections(extra),
        *gpu_readiness_section(result),
        *gpu_section(result),
        "## Cost follows activity",
        activity_table(extra),
        "## Speed work in the measured code",
        "\n".join(f"- {note}" for note in s.get("notes", [])) or "–",
    ]
    return "\n\n".join(parts) + "\n"
