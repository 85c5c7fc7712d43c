"""The bench's GPU section on a machine where pybullet cannot be installed, in two halves.

``make bench`` measures everything in one process and needs pybullet for its scenes. On a GPU
machine without pybullet (no wheel for its Python), split it:

1. here, with pybullet: ``python scripts/device_bench.py prepare DIR`` generates the bench's
   inputs (training trajectories, the piles in motion of ``gpu.rollout_sizes``, and the
   crossover's truth windows at ``SIZES``) in ``DIR/inputs.pt``; ``... cpu DIR RUN ...``
   measures the crossover there on this CPU (each RUN against pybullet), ``DIR/cpu.pt``;
2. on the GPU: ``python scripts/device_bench.py measure DIR OUT [RUN ...]`` runs
   :func:`physgnn.benchmark.gpu.gpu_section` (training steps/s per precision variant, rollout
   FPS per size) and each RUN's crossover rollouts on the GPU (scores and FPS over the same
   windows); ``OUT/device_bench.json``;
3. here: ``python scripts/device_bench.py render DIR OUT/device_bench.json`` writes the
   markdown of both (``DIR/gpu.md``): the GPU section as bench.md shows it, and the same work
   (MSE20 against the same truth) with the learned simulator on the GPU beside pybullet on this
   CPU, each learned row judged against the engine rows as the crossover judges them.

RUN is a run folder or ``pretrained``. The engine rows are timed here, not on the GPU
machine's CPU: pybullet has no GPU path, and the GPU machine could not run it.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from statistics import median

import numpy as np
import torch
from omegaconf import OmegaConf

from physgnn.cli.overrides import compose_config

SIZES = (154, 1000, 3000)  # crossover windows
ROUNDS = 3


QUICK = os.environ.get("DEVICE_BENCH_QUICK") == "1"  # tiny sizes, the CPU as the device (a test)


def bench_config():
    cfg = compose_config("bench", ["run=null"])
    if not QUICK:
        return cfg
    cfg = compose_config("bench", ["run=null", "gpu.device=cpu"])
    return OmegaConf.merge(cfg, {"gpu": cfg.quick_settings.gpu})


def sizes() -> tuple[int, ...]:
    return (30,) if QUICK else SIZES


def prepare(folder: Path) -> None:
    from physgnn.benchmark import scenes
    from physgnn.benchmark.crossover import truth_windows
    from physgnn.data.stats import compute_stats

    cfg = bench_config()
    torch.set_num_threads(1)
    rng = np.random.default_rng(int(cfg.seed))
    train = scenes.training_trajectories(cfg, rng)
    moving = {n: scenes.bench_run(cfg, n, rng) for n in cfg.gpu.rollout_sizes}
    windows = {n: truth_windows(cfg, n, rng, int(cfg.model.H), {})["landed"] for n in sizes()}
    folder.mkdir(parents=True, exist_ok=True)
    stats = compute_stats(train)
    inputs = {"train": train, "stats": stats, "moving": moving, "windows": windows}
    torch.save(inputs, folder / "inputs.pt")


def on_cpu(folder: Path, runs: list[str]) -> None:
    """The crossover's rows on this CPU (1 thread): each RUN and pybullet at every substep
    count, interleaved, over the saved windows; ``DIR/cpu.pt``."""
    from physgnn.benchmark.crossover import as_loaded, taking_turns
    from physgnn.benchmark.crossover_summary import judged, summary
    from physgnn.training.runs import load_run

    cfg = bench_config()
    torch.set_num_threads(1)
    windows = torch.load(folder / "inputs.pt", weights_only=False)["windows"]
    cpu = {}
    for run in runs:
        sim = load_run(run)[0].eval()
        cpu[run] = {}
        for n, window in windows.items():
            load = os.getloadavg()[0]
            turns = [as_loaded(run, sim, 1)]
            rows = summary([taking_turns(turns, window, {}, list(cfg.crossover.substeps), ROUNDS)])
            cpu[run][n] = {"rows": rows, **judged(rows), "loadavg": [load, os.getloadavg()[0]]}
            print(f"cpu: {run} n={n}: {judged(rows)}", flush=True)
    torch.save(cpu, folder / "cpu.pt")


def measure(folder: Path, out: Path, runs: list[str]) -> None:
    from physgnn.benchmark.gpu import gpu_section
    from physgnn.metrics import trajectory_metrics
    from physgnn.rollout import rollout
    from physgnn.training.runs import load_run

    cfg = bench_config()
    inputs = torch.load(folder / "inputs.pt", weights_only=False)
    device = torch.device(cfg.gpu.device)
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else str(device)
    result = {"device": name, "crossover": {}}
    for run in runs:
        sim = load_run(run)[0].to(device).eval()
        result["crossover"][run] = {}
        for n, window in inputs["windows"].items():
            rollout(sim, [window.truncated(sim.H + 3)])  # warm-up
            fps, pred = [], None
            for _ in range(ROUNDS):
                pred = rollout(sim, [window])[0]
                fps.append(pred.fps)
            m = trajectory_metrics(pred, window, horizon=20)
            row = {k: m.get(k) for k in ("mse20", "chamfer", "depth_sphere", "depth_ground")}
            row |= {"fps": median(fps), "fps_rounds": fps, "diverged_at": pred.diverged_at}
            result["crossover"][run][n] = row
            print(f"measure: {run} n={n}: {row}", flush=True)
        _write(out, result)
    # one variant at a time, written after each: a run cut short keeps what it measured
    runs_in = {n: {"traj": t} for n, t in inputs["moving"].items()}
    parts = [{"variants": ["eager"], "rollout_variants": ["eager"]}]
    parts += [{"variants": [v], "rollout_variants": []} for v in cfg.gpu.variants if v != "eager"]
    parts += [
        {"variants": [], "rollout_variants": [v]} for v in cfg.gpu.rollout_variants if v != "eager"
    ]
    for part in parts:
        section = gpu_section(
            OmegaConf.merge(cfg, {"gpu": part}), inputs["train"], inputs["stats"], runs_in
        )
        gpu = result.setdefault("gpu", section | {"training": [], "rollout": []})
        gpu["training"] += section["training"]
        gpu["rollout"] += section["rollout"]
        _write(out, result)


def _write(out: Path, result: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "device_bench.json").write_text(json.dumps(result, indent=1, default=str))


def render(folder: Path, measured: Path) -> None:
    from physgnn.benchmark.markdown import gpu_section

    cpu_rows = torch.load(folder / "cpu.pt", weights_only=False)
    result = json.loads(measured.read_text())
    lines = [f"# The bench on a GPU: {result['device']}", ""]
    lines += gpu_section({"gpu": result.get("gpu")})
    lines += ["", "## The same work: the learned simulator on the GPU, pybullet on the CPU", ""]
    lines += same_work_table(result["crossover"], cpu_rows)
    (folder / "gpu.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {folder / 'gpu.md'}")


def engine_rows(cpu_rows: dict, n: int) -> list[dict]:
    """pybullet's rows at ``n`` spheres, each setting at the highest FPS it reached in the
    runs' rounds (the least loaded moment: the engine is never made to look slower than it
    was measured); the scores are the same in every run (the same start, deterministic)."""
    measured = [cpu_rows[run][n]["rows"][1:] for run in cpu_rows]
    return [max(rows, key=lambda r: r["fps"]) for rows in zip(*measured, strict=True)]


def same_work_table(crossover: dict, cpu_rows: dict) -> list[str]:
    """Per size: pybullet's rows, then each run's learned rows on the CPU and on the GPU, each
    judged against those engine rows as the crossover judges (front, matched setting)."""
    from physgnn.benchmark.crossover_summary import judged
    from physgnn.report.format import fmt, md_table

    body = []
    for n in sorted({int(n) for sizes in crossover.values() for n in sizes}):
        engine = engine_rows(cpu_rows, n)
        for e in engine:
            body.append(
                [
                    str(n),
                    f"pybullet-{e['substeps']} (CPU)",
                    fmt(e["mse20"]),
                    f"{e['fps']:.1f}",
                    "",
                    "",
                    "",
                ]
            )
        for run, sizes in crossover.items():
            cpu = cpu_rows[run][n]["rows"][0]
            measured = sizes[str(n)]
            diverged = int(measured["diverged_at"] is not None)
            gpu = {**cpu, **measured, "substeps": None, "diverged": diverged}
            for where, row in (("CPU", cpu), ("GPU", gpu)):
                j = judged([row] + engine)
                best = next((e for e in engine if e["substeps"] == j["matched_substeps"]), None)
                ratio = "–" if best is None else f"{row['fps'] / best['fps']:.2f}×"
                body.append(
                    [
                        str(n),
                        f"{run} ({where})",
                        fmt(row["mse20"]),
                        f"{row['fps']:.1f}",
                        "on" if j["on_front"] else "off",
                        str(j["matched_substeps"]),
                        ratio,
                    ]
                )
    header = [
        "spheres",
        "simulator",
        "MSE20",
        "FPS (median)",
        "MSE20 front",
        "matched",
        "FPS / matched FPS",
    ]
    return [md_table(header, body)]


if __name__ == "__main__":
    verb, args = sys.argv[1], sys.argv[2:]
    if verb == "prepare":
        prepare(Path(args[0]))
    elif verb == "cpu":
        on_cpu(Path(args[0]), args[1:])
    elif verb == "measure":
        measure(Path(args[0]), Path(args[1]), args[2:])
    elif verb == "render":
        render(Path(args[0]), Path(args[1]))
    else:
        sys.exit(f"usage: {__doc__.splitlines()[0]} (prepare | cpu | measure | render)")
