"""``make bench``: what accuracy costs in time, in one run (:func:`bench`).

Measures the machine (CPU, threads, fp32 matmul rate), the learned simulator per configuration
and scene size (ms per frame split into graph / network / integration, FPS, FLOPs and the share
of the matmul rate), pybullet on the same scenes (FPS at 10 substeps; at one size, FPS and
accuracy against a fine reference for several substep counts), the training throughput of the
baseline and the cost of idle spheres, contacts and walls, and the speed ratio of learned steps
to pybullet on the same frames in interleaved rounds (:mod:`.interleaved`), and the crossover:
a trained model against pybullet at several substep counts on landed piles of growing size,
the speed target judged against the setting of matched accuracy (:mod:`.crossover`). Writes
``bench.json`` (the headline numbers), ``bench_extra.json`` (everything else), pybullet's
accuracy-versus-time curve on the bench pile (``pybullet_accuracy.png``) and ``bench.md``.

Scenes are random_box scenes in motion: pybullet runs ``warmup_frames`` from the initial
state, and the timed frames start from there, so learned steps (one step per ground-truth
frame) see the contacts of a real pile. The learned rows run the trained model of ``run``
(:mod:`.source`; its graph rebuilds within a frame are a trained model's), the configurations
that change the architecture random weights of the same model. ``large=true`` merges
``large_settings`` (the large sizes, more draws), ``quick=true`` then ``quick_settings``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, ListConfig, OmegaConf

from physgnn.benchmark import activity, machine, profile, scenes
from physgnn.benchmark.crossover import crossover
from physgnn.benchmark.gpu import gpu_section
from physgnn.benchmark.gpu_readiness import gpu_readiness
from physgnn.benchmark.interleaved import interleaved_rows
from physgnn.benchmark.learned import batched_rows, build_simulators, learned_rows
from physgnn.benchmark.markdown import ACCURACY_FIGURE, write_markdown
from physgnn.benchmark.pybullet import accuracy_sweep, pybullet_rows, pybullet_runs
from physgnn.benchmark.source import BenchError, learned_source
from physgnn.data.stats import compute_stats
from physgnn.files import claimed, write_json, write_text
from physgnn.ranges import FLAG, whole
from physgnn.report.pareto import bench_figure

# The bench's switches: true or false (``quick=maybe`` is refused, not taken as true).
FLAGS = ("quick", "large", "overwrite")
# A bench scene's size: random_box with exactly this many spheres.
SIZE = whole(1, what="spheres of a bench scene", example=154, exact=True)
# The sections of conf/bench.yaml that every bench measures (crossover=null leaves its phase out)
ALWAYS_RUN = (
    "machine",
    "learned",
    "interleaved",
    "rollout_sizes",
    "batched",
    "accuracy",
    "training",
    "profile",
    "gpu_readiness",
    "gpu",
    "activity",
)


def bench(cfg: DictConfig) -> dict:
    """Run every measurement of ``cfg`` (see ``conf/bench.yaml``); returns bench.json's dict.
    An ``out_dir`` holding files physgnn did not write is refused unless ``overwrite=true``
    (:func:`physgnn.files.claim_folder`), before anything is measured."""
    for key in FLAGS:
        FLAG.check(key, cfg.get(key), error=BenchError)
    cfg = merged_config(cfg, command_line())
    check_settings(cfg)
    ours = Path(cfg.out_dir) == Path(cfg.paths.bench_dir)
    overwrite = bool(cfg.get("overwrite"))
    with claimed(cfg.out_dir, "out_dir", overwrite, ours):  # a failed bench leaves no folder
        return _measured(cfg)


def _measured(cfg: DictConfig) -> dict:
    """:func:`bench`'s measurements, written into ``cfg.out_dir``; bench.json's dict."""
    torch.set_num_threads(int(cfg.threads))
    torch.manual_seed(int(cfg.seed))
    start = time.perf_counter()
    info = machine.machine_info(int(cfg.threads), cfg.machine.shapes, cfg.machine.repeats)
    print(
        f"machine: {info['cpu']}, {info['threads']} threads, {info['matmul_gflops']:.1f} GFLOP/s",
        flush=True,
    )
    phases: dict[str, float] = {}
    m = measure(cfg, np.random.default_rng(int(cfg.seed)), info["matmul_gflops"], phases)
    result = {
        "wall_s": time.perf_counter() - start,
        "run": m["source"].label,
        "machine": {k: info[k] for k in ("cpu", "threads", "matmul_gflops")},
        "learned": [{k: r[k] for k in LEARNED_KEYS} for r in m["learned"]],
        "pybullet": pybullet_rows(cfg, m["runs"], m["pybullet_accuracy"]),
        "interleaved": m["interleaved"],
        "crossover": m["crossover"],
        "training": {
            k: m["training"][k] for k in ("pairs_per_s", "nodes_per_s", "share_of_matmul")
        },
        "gpu_readiness": {
            part: {k: v for k, v in counts.items() if k != "where"}
            for part, counts in m["gpu_readiness"].items()
        },
        "gpu": m["gpu"],
    }
    extra = {
        "machine": info,
        **{k: v for k, v in m.items() if k not in ("runs", "interleaved", "crossover", "source")},
        "settings": OmegaConf.to_container(cfg, resolve=True),
        "learned_model": OmegaConf.to_container(m["source"].model, resolve=True),
        "wall_s": result["wall_s"],
        "phase_s": phases,
        "loadavg_end": os.getloadavg()[0],
    }
    write_outputs(Path(cfg.out_dir), result, extra)
    print(f"bench: {extra['wall_s']:.0f} s; wrote {Path(cfg.out_dir) / 'bench.md'}", flush=True)
    return result


def check_settings(cfg: DictConfig) -> None:
    """Refuse in one line what the bench cannot run: threads below 1, a size that is no whole
    number of spheres, a phase other than the crossover left out, an interleaved
    configuration that is not a learned one."""
    if int(cfg.threads) < 1:
        raise BenchError(f"threads must be >= 1 (got {cfg.threads})")
    check_sizes(cfg.get("sizes"))
    left_out = [key for key in ALWAYS_RUN if cfg.get(key) is None]
    if left_out:
        raise BenchError(
            f"{left_out[0]}=null: make bench runs this phase every time; only crossover=null "
            "leaves a phase out (quick=true makes every phase short)"
        )
    unknown = [c for c in cfg.interleaved.configs if c not in cfg.learned.configs]
    if unknown:
        raise BenchError(
            f"interleaved.configs names {', '.join(unknown)}, not among learned.configs "
            f"({', '.join(cfg.learned.configs)})"
        )


def check_sizes(sizes) -> None:
    """``sizes`` is a list of scene sizes, each a whole number of spheres (:data:`SIZE`)."""
    if not isinstance(sizes, ListConfig | list) or not sizes:
        raise BenchError(
            f"sizes must be a list of whole numbers >= 1 (spheres of a bench scene), got "
            f"{sizes!r} (e.g. sizes=[154,1000])"
        )
    for i, n in enumerate(sizes):
        SIZE.check(f"sizes[{i}]", n, "e.g. sizes=[154,1000]", error=BenchError)


def measure(cfg: DictConfig, rng: np.random.Generator, matmul: float, phases: dict) -> dict:
    """Every measurement in order, the seconds of each phase written to ``phases``."""

    def timed(name: str, fn, *args):
        t0 = time.perf_counter()
        out = fn(*args)
        phases[name] = time.perf_counter() - t0
        return out

    train_trajs = timed("training data", scenes.training_trajectories, cfg, rng)
    stats = compute_stats(train_trajs)
    source = timed("loading the run", learned_source, cfg, stats)
    m = {"source": source, "runs": timed("pybullet sizes", pybullet_runs, cfg, rng)}
    runs = m["runs"]
    sims = build_simulators(cfg, source)
    m["learned"] = timed("learned", learned_rows, cfg, runs, sims, matmul)
    m["interleaved"] = timed("interleaved", interleaved_rows, cfg, runs, sims)
    start = runs[cfg.accuracy.n_spheres]["start"]
    m["pybullet_accuracy"] = timed("pybullet substeps", accuracy_sweep, cfg, start)
    m["training"] = timed("training", activity.training_throughput, cfg, train_trajs, stats, matmul)
    m["profile"] = timed("profile", profile.training_profile, cfg, train_trajs, stats, matmul)
    m["activity"] = timed("activity", activity.activity_rows, cfg, runs, source, rng)
    m["rollout"] = timed("rollout", activity.rollout_rows, cfg, runs, source)
    m["batched"] = timed("batched", batched_rows, cfg, runs, source)
    moving = runs[cfg.gpu_readiness.rollout_size]["traj"]
    m["gpu_readiness"] = timed("gpu readiness", gpu_readiness, cfg, train_trajs, stats, moving)
    m["gpu"] = timed("gpu", gpu_section, cfg, train_trajs, stats, runs)
    m["crossover"] = timed("crossover", crossover, cfg, rng, source)
    return m


# The mappings that quick_settings replaces whole (a shorter list of configurations or learned
# settings), where the rest of it is merged key by key.
REPLACED = ("learned.configs", "crossover.learned_settings")


def merged_config(cfg: DictConfig, given: Sequence[str] = ()) -> DictConfig:
    """``cfg`` with ``large_settings`` merged over it key by key when ``large`` is true, then
    :func:`quick_config` when ``quick`` is true; then the command line's own ``key=value``
    settings ``given`` once more, so that a key set alone wins over the blocks
    (``quick=true run=pretrained`` runs the shipped weights)."""
    merged = cfg
    if cfg.get("large"):
        merged = settings_merged(merged, cfg.large_settings, replaced=())
    if cfg.quick:
        merged = quick_config(merged)
    if merged is cfg:
        return cfg
    alone = [g for g in given if g.split("=")[0] not in ("quick", "large") and g[:1] not in "+~"]
    return OmegaConf.merge(merged, OmegaConf.from_dotlist(alone)) if alone else merged


def command_line() -> list[str]:
    """The ``key=value`` settings of the command line that composed the config (none outside
    a Hydra command)."""
    if not HydraConfig.initialized():
        return []
    return list(HydraConfig.get().overrides.task)


def quick_config(cfg: DictConfig) -> DictConfig:
    """``cfg`` with ``quick_settings`` merged over it, its mappings of :data:`REPLACED`
    replacing the full ones."""
    return settings_merged(cfg, cfg.quick_settings, REPLACED)


def settings_merged(cfg: DictConfig, block: DictConfig, replaced: tuple) -> DictConfig:
    """``cfg`` with the settings ``block`` merged over it; a mapping of ``replaced`` that the
    block gives replaces the full one (not merged into it); a section that ``cfg`` turns off
    (``crossover=null``) stays off."""
    cfg = cfg.copy()
    OmegaConf.set_struct(cfg, False)
    for key in replaced:
        given = OmegaConf.select(block, key)
        if given is not None and OmegaConf.select(cfg, key) is not None:
            OmegaConf.update(cfg, key, given, merge=False)
    off = [key for key in block if key in cfg and cfg[key] is None]
    merged = OmegaConf.merge(cfg, block)
    for key in off:
        merged[key] = None
    return merged


LEARNED_KEYS = (
    "config",
    "weights",
    "n_spheres",
    "fps",
    "graph_ms",
    "network_ms",
    "integrate_ms",
    "gflop_per_step",
    "share_of_matmul",
)


def write_outputs(out_dir: Path, result: dict, extra: dict) -> None:
    """``bench.json``, ``bench_extra.json``, pybullet's accuracy-versus-time curve on the bench
    pile (``pybullet_accuracy.png``) and ``bench.md`` in ``out_dir``, atomically."""
    write_json(out_dir / "bench.json", result)
    write_json(out_dir / "bench_extra.json", extra)
    bench_figure(out_dir / ACCURACY_FIGURE, result, extra)
    write_text(out_dir / "bench.md", write_markdown(result, extra))
