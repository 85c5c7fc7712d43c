"""How ready a training step and a rollout frame are for a GPU, counted on any device.

Per training step (the default recipe: input noise, contact noise, push-forward, the loss and
its contact penalty, backward, clipping and Adam, through Lightning as ``make train`` runs it)
and per rollout frame (:func:`physgnn.rollout.rollout` of the learned model): the host round
trips (``syncs``, host-to-device ``copies`` included) and aten ops (``kernels``) of
:mod:`physgnn.benchmark.syncs`, and the host time in ms with a tiny network (``hidden`` small,
so the arithmetic does not hide the overhead). The neighbour backend is ``torch``, which is what
``auto`` picks on CUDA without torch-cluster. Counts are the maxima over the steps (push-forward
lengths vary), times means.

Compiled (``lit.compile.enabled=true``'s regions, :meth:`~physgnn.training.lit.LitSimulator.
compile_regions`): only ``kernels`` can be counted, as the aten ops dispatched outside the
compiled regions (:class:`~physgnn.benchmark.syncs.OpsOutsideRegions`; dynamo runs eager under
the sync counter). They are the same for every compile backend, so the regions are compiled
with ``aot_eager`` (seconds, no code generation), and no host time is given.

"""

from __future__ import annotations

import time
from collections import Counter

import lightning as L
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from physgnn.benchmark.learned import measuring_trainer
from physgnn.benchmark.syncs import counting, profiling_ops
from physgnn.data.pairs import EpochSampler, PairDataset, pair_loader
from physgnn.models.capture import compile_simulator
from physgnn.report.format import fmt_as
from physgnn.rollout import rollout

_COUNTS = ("syncs", "kernels", "copies")  # copies are counted in syncs too


class StepCounter(L.Callback):
    """Counts the syncs and kernels of the even training steps (batch start to batch end) and
    times the odd ones: the counting mode runs Python for every op, which would inflate the
    host time of a step it watches. ``where`` sums the Python lines of the syncs from batch
    ``warmup`` on."""

    def __init__(self, warmup: int = 0, record_where: bool = False, profile: bool = False):
        self.warmup, self.record_where, self.profile = warmup, record_where, profile
        self.steps: list[dict] = []
        self.where: Counter = Counter()
        self._context = self._counter = None

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
        if batch_idx == self.warmup:
            self.where.clear()
        if self.profile:  # every step, its kernels only
            self._context, self._graphs = profiling_ops(), compiled_graphs()
        else:
            self._context = counting(self.record_where) if batch_idx % 2 == 0 else None
        self._counter = self._context.__enter__() if self._context is not None else None
        self._t0 = time.perf_counter()

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
        ms = 1000 * (time.perf_counter() - self._t0)
        if self._context is None:
            self.steps.append({"host_ms": ms})
            return
        self._context.__exit__(None, None, None)
        counter = self._counter
        if self.profile and compiled_graphs() != self._graphs:
            self.steps.append({"compiling": True})  # its tracing is not what a step costs
            return
        self.steps.append({key: getattr(counter, key, None) for key in _COUNTS})
        self.where.update(getattr(counter, "where", ()))


def compiled_graphs() -> int:
    """Graphs dynamo has compiled in this process so far."""
    return torch._dynamo.utils.counters["stats"]["unique_graphs"]


def training_step_counts(
    model_cfg: DictConfig,
    lit_cfg: DictConfig,
    trajectories: list,
    stats: dict,
    c: DictConfig,
    compiled: bool = False,
) -> dict:
    """``{"syncs", "kernels", "host_ms", "where"}`` of ``c.steps`` counted and ``c.steps``
    timed training steps, alternated, after ``c.warmup_steps`` (batch ``c.batch_size``);
    ``syncs`` and ``kernels`` the maxima, host ms the mean, ``where`` the syncs per source line
    per counted step. ``compiled``: the module doc's kernels outside compiled regions only."""
    simulator = instantiate(model_cfg, stats=stats)
    lit = instantiate(lit_cfg, simulator=simulator)
    if compiled:
        lit.compile_regions(backend="aot_eager")
    data = PairDataset(trajectories, simulator.H, future=int(lit_cfg.pushforward.steps))
    total = int(c.warmup_steps + 2 * c.steps)
    loader = pair_loader(data, int(c.batch_size), EpochSampler(len(data), total * c.batch_size, 0))
    counter = StepCounter(int(c.warmup_steps), record_where=True, profile=compiled)
    trainer = measuring_trainer(total, [counter], gradient_clip_val=1.0)
    trainer.fit(lit, train_dataloaders=loader)
    after = counter.steps[int(c.warmup_steps) :]
    counted = [s for s in after if "kernels" in s]
    timed = [s for s in after if "host_ms" in s]
    return summary(counted, timed, counter.where, len(counted))


def rollout_frame_counts(
    model_cfg: DictConfig, stats: dict, trajectory, frames: int, compiled: bool = False
) -> dict:
    """``{"syncs", "kernels", "host_ms", "where"}`` per frame of a learned rollout from
    ``trajectory``'s start: the difference between rollouts of ``2·frames`` and ``frames``
    frames, over ``frames`` (what each further frame costs, without the start and the end);
    counted in one pair of rollouts and timed in another (the counting mode's own Python per
    op would inflate the time). ``compiled``: the module doc's kernels outside compiled
    regions only."""
    simulator = instantiate(model_cfg, stats=stats).eval()
    if compiled:
        compile_simulator(simulator, backend="aot_eager")

    def go(n: int) -> None:
        rollout(simulator, [trajectory], n_frames=simulator.H + 1 + n)

    go(2 * frames)  # warm-up (compiled: the compiles of every region)
    counted = {}
    for n in (frames, 2 * frames):
        with profiling_ops() if compiled else counting(record_where=True) as counter:
            go(n)
        counted[n] = counter
    ms = {}
    for n in () if compiled else (frames, 2 * frames):
        t0 = time.perf_counter()
        go(n)
        ms[n] = 1000 * (time.perf_counter() - t0)
    short, long = counted[frames], counted[2 * frames]
    step = {key: _per_frame(short, long, key, frames) for key in _COUNTS}
    where = getattr(long, "where", Counter())
    where.subtract(getattr(short, "where", Counter()))
    timed = [{"host_ms": (ms[2 * frames] - ms[frames]) / frames}] if ms else []
    return summary([step], timed, +where, frames)


def _per_frame(short, long, key: str, frames: int) -> float | None:
    if not hasattr(long, key):
        return None
    return (getattr(long, key) - getattr(short, key)) / frames


_KINDS = {"": {}, "_fixed_capacity": {"fixed": True}, "_compiled": {"compiled": True}}


def gpu_readiness(cfg: DictConfig, trajectories: list, stats: dict, start) -> dict:
    """``{"train_step", "rollout_frame"}`` and the same two with the suffixes
    ``_fixed_capacity`` and ``_compiled``, each ``{"syncs", "kernels", "copies", "host_ms",
    "where"}`` (bench.json's ``gpu_readiness``; ``where`` of each goes to bench_extra.json): the
    module doc's counts with counted graphs, with graphs of fixed capacity
    (``model.graph.fixed_capacity=true``, what a captured step uses), and compiled (kernels
    only; left out with ``gpu_readiness.compiled=false``); ``start``: a bench scene in motion,
    the rollout's first frames."""
    c, out = cfg.gpu_readiness, {}
    for suffix, kind in _KINDS.items():
        fixed, compiled = kind.get("fixed", False), kind.get("compiled", False)
        if compiled and not c.compiled:
            continue
        model = OmegaConf.merge(cfg.model, c.model, {"graph": {"fixed_capacity": fixed}})
        train = training_step_counts(model, c.lit, trajectories, stats, c, compiled)
        frame = rollout_frame_counts(model, stats, start, int(c.rollout_frames), compiled)
        print(
            f"gpu readiness{suffix.replace('_', ' ')}: training step "
            f"{fmt_as(train['syncs'], '')} syncs, {fmt_as(train['kernels'], '')} kernels, "
            f"{fmt_as(train['host_ms'], '.1f')} ms; rollout frame {fmt_as(frame['syncs'], '.1f')} "
            f"syncs, {frame['kernels']:.0f} kernels, {fmt_as(frame['host_ms'], '.1f')} ms",
            flush=True,
        )
        out |= {f"train_step{suffix}": train, f"rollout_frame{suffix}": frame}
    return out


def summary(counted: list[dict], timed: list[dict], where: Counter, per: int) -> dict:
    """Maxima of the counts (None where not counted, or no step was: every step compiled),
    mean host ms of the timed steps (None without any) and the sync lines per step (or
    frame)."""
    values = {key: [s[key] for s in counted if s[key] is not None] for key in _COUNTS}
    return {
        **{key: max(v) if v else None for key, v in values.items()},
        "host_ms": sum(s["host_ms"] for s in timed) / len(timed) if timed else None,
        "where": {k: v / per for k, v in where.most_common()},
    }
