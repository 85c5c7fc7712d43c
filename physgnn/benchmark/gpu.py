"""The bench on a GPU: training steps per second, rollout frames per second and peak memory.

Run by ``make bench`` when torch sees a CUDA device (otherwise one line says it was skipped):

- **training**: optimiser steps per second and spheres per second of the default recipe
  (input noise, contact noise, push-forward of U{0..K} steps, the loss, backward, clipping,
  Adam) at the default batch, for each ``variant``: ``eager``; ``tf32`` (fp32 matrix products
  as TF32, ``matmul_precision=high``); ``bf16`` (autocast to bfloat16, as
  ``trainer.precision=bf16-mixed``); ``compiled`` (``lit.compile.enabled=true``'s regions,
  dynamic shapes, :meth:`~physgnn.training.lit.LitSimulator.compile_regions`); ``captured`` (graphs
  of fixed capacity, nothing read back while they are built, padded to buckets, and the
  network compiled with ``mode="reduce-overhead"``: CUDA graphs);
- **rollout**: frames per second of the baseline through :func:`physgnn.rollout.rollout` on
  the bench scenes of ``rollout_sizes``, for each of ``rollout_variants``: ``eager``, or
  ``compiled`` (:func:`~physgnn.models.capture.compile_simulator`);
- the peak memory of each row (``torch.cuda.max_memory_allocated``).

The same functions run on any device (the tests run them on the CPU with tiny settings).
"""

from __future__ import annotations

import contextlib
import time
from functools import partial

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from physgnn.data.pairs import EpochSampler, PairDataset, pair_loader
from physgnn.models.capture import compile_simulator
from physgnn.rollout import rollout

VARIANTS = ("eager", "tf32", "bf16", "compiled", "captured")
ROLLOUT_VARIANTS = ("eager", "compiled")


def gpu_section(cfg: DictConfig, trajectories: list, stats: dict, runs: dict) -> dict | None:
    """``{"device", "batch_size", "training": [...], "rollout": [...]}`` (module doc) on
    ``cfg.gpu.device`` (``cuda`` by default), or None with one line when that is CUDA and torch
    sees none. A row that fails holds its ``error`` instead of its figures."""
    c = cfg.gpu
    device = torch.device(c.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        print("gpu: skipped (torch sees no CUDA device)", flush=True)
        return None
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else str(device)
    training = [
        _row(partial(training_row, cfg, trajectories, stats, device, v), {"variant": v}, device)
        for v in c.variants
    ]
    sizes = [n for n in c.rollout_sizes if n in runs]
    frames = [
        _row(
            partial(rollout_row, cfg.model, stats, runs[n]["traj"], device, v),
            {"n_spheres": n, "variant": v},
            device,
        )
        for n in sizes
        for v in c.rollout_variants
    ]
    return {
        "device": name,
        "batch_size": int(c.batch_size),
        "training": training,
        "rollout": frames,
    }


def _row(measure, names: dict, device: torch.device) -> dict:
    """``measure()``, or ``names`` with the error where it failed (one row of the GPU section
    is never worth the whole bench, measured over minutes); printed either way."""
    try:
        row = measure()
    except Exception as err:  # noqa: BLE001 (reported in the row and in bench.md)
        row = names | {"error": f"{type(err).__name__}: {err}".splitlines()[0][:300]}
    figure = row.get("steps_per_s", row.get("fps"))
    what = "FAILED " + row["error"] if "error" in row else f"{figure:.1f} per s"
    print(f"gpu {' '.join(f'{k}={v}' for k, v in names.items())}: {what}", flush=True)
    if device.type == "cuda":
        torch.cuda.empty_cache()
    return row


@contextlib.contextmanager
def _variant(variant: str, device: torch.device):
    """The precision settings of ``variant`` for the duration (module doc)."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown gpu.variants entry '{variant}'; choose from {list(VARIANTS)}")
    before = torch.get_float32_matmul_precision()
    torch.set_float32_matmul_precision("high" if variant == "tf32" else "highest")
    autocast = torch.autocast(device.type, dtype=torch.bfloat16, enabled=variant == "bf16")
    try:
        with autocast:
            yield
    finally:
        torch.set_float32_matmul_precision(before)


def _lit(cfg: DictConfig, stats: dict, device: torch.device, variant: str):
    # captured: graphs of fixed capacity, padded to buckets (LearnedSimulator.padded)
    model = OmegaConf.merge(cfg.model, {"graph": {"fixed_capacity": variant == "captured"}})
    simulator = instantiate(model, stats=stats)
    lit = instantiate(cfg.gpu.lit, simulator=simulator).to(device)
    if variant == "captured":  # padded graphs: the network alone, fixed shapes
        lit.compile_regions("reduce-overhead", 64)
    elif variant == "compiled":
        lit.compile_regions()
    lit.optimizer = lit.optimizer_factory(lit.parameters())
    return lit


def training_row(cfg, trajectories: list, stats: dict, device, variant: str) -> dict:
    """Steps per second, spheres per second and peak memory of ``cfg.gpu.steps`` timed steps
    after ``cfg.gpu.warmup_steps`` (module doc)."""
    c = cfg.gpu
    _reset_peak(device)
    lit = _lit(cfg, stats, device, variant)
    pairs = PairDataset(trajectories, lit.simulator.H, future=int(c.lit.pushforward.steps))
    pairs = pairs.to(device)
    total, size = int(c.warmup_steps + c.steps), int(c.batch_size)
    batches = pair_loader(pairs, size, EpochSampler(len(pairs), total * size, seed=0))
    nodes, start = 0, None
    with _variant(variant, device):
        for step, batch in enumerate(batches):
            if step == c.warmup_steps:
                _sync(device)
                start, nodes = time.perf_counter(), 0
            _optimiser_step(lit, batch, step)
            nodes += batch.num_nodes
    _sync(device)
    seconds = time.perf_counter() - start
    return {
        "variant": variant,
        "batch_size": int(c.batch_size),
        "steps_per_s": c.steps / seconds,
        "nodes_per_s": nodes / seconds,
        "peak_mib": _peak_mib(device),
    }


def _optimiser_step(lit, batch, step: int) -> None:
    lit._unroll_length = lambda: lit.pushforward.steps if step % 2 else 0  # mean of U{0..2}
    loss = lit.training_step(batch, step)
    lit.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(lit.parameters(), 1.0)
    lit.optimizer.step()


def rollout_row(model_cfg: DictConfig, stats: dict, traj, device, variant: str = "eager") -> dict:
    """Frames per second and peak memory of the baseline rolled out over ``traj``, eager or
    ``compiled`` (module doc)."""
    if variant not in ROLLOUT_VARIANTS:
        raise ValueError(
            f"unknown gpu.rollout_variants entry '{variant}'; choose from {list(ROLLOUT_VARIANTS)}"
        )
    _reset_peak(device)
    simulator = instantiate(model_cfg, stats=stats).to(device).eval()
    if variant == "compiled":
        compile_simulator(simulator)
    rollout(simulator, [traj], n_frames=simulator.H + 3)  # warm-up (and compiles)
    [result] = rollout(simulator, [traj], n_frames=traj.n_frames)
    fps, peak = result.fps, _peak_mib(device)
    return {"n_spheres": traj.n_spheres, "variant": variant, "fps": fps, "peak_mib": peak}


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _reset_peak(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)


def _peak_mib(device: torch.device) -> float | None:
    if device.type != "cuda":
        return None
    return torch.cuda.max_memory_allocated(device) / 2**20
