"""What else a bench run measures: the training throughput of the baseline, the cost of idle
spheres, contacts and walls (all timed together), and the rollout path ``make eval`` times."""

from __future__ import annotations

import time

import lightning as L
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from physgnn.benchmark.learned import frame_states, measuring_trainer, time_cases
from physgnn.benchmark.profile import step_flops
from physgnn.benchmark.scenes import bench_run, resting_scene, with_effects, without_walls
from physgnn.benchmark.source import Source
from physgnn.data.pairs import EpochSampler, PairDataset, pair_loader
from physgnn.groundtruth.engine import simulate
from physgnn.models.profiling import StepTimer
from physgnn.models.sleeping import SleepingSimulator
from physgnn.rollout import rollout


class ThroughputTimer(L.Callback):
    """State pairs and nodes per second over the training batches after ``warmup``;
    ``first_graph``: how many graphs ``graphs`` (a watching StepTimer's) held when the timed
    batches began."""

    def __init__(self, warmup: int, graphs: StepTimer):
        self.warmup, self.graphs = warmup, graphs
        self.t0 = self.t1 = None
        self.pairs = self.nodes = self.steps = self.first_graph = 0

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
        if batch_idx == self.warmup:
            self.t0 = time.perf_counter()
            self.first_graph = len(self.graphs.sizes)

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
        if batch_idx >= self.warmup:
            self.t1 = time.perf_counter()
            self.pairs += batch.num_graphs
            self.nodes += batch.num_nodes
            self.steps += 1


def training_throughput(cfg: DictConfig, trajectories: list, stats: dict, matmul: float) -> dict:
    """Baseline training (Lightning, Adam, noise) for ``training.steps`` batches; pairs/s,
    nodes/s and the FLOP rate (GFLOP/s, share of the ``matmul`` rate; FLOPs as
    :func:`physgnn.benchmark.profile.step_flops` counts them) after ``warmup_steps`` (data
    loading included)."""
    c = cfg.training
    simulator = instantiate(cfg.model, stats=stats)
    lit = instantiate(c.lit, simulator=simulator)
    data = PairDataset(trajectories, simulator.H)
    sampler = EpochSampler(len(data), c.steps * c.batch_size, int(cfg.seed))
    loader = pair_loader(data, c.batch_size, sampler)
    graphs = StepTimer()
    timer = ThroughputTimer(min(c.warmup_steps, c.steps - 1), graphs)
    trainer = measuring_trainer(c.steps, [timer])
    with graphs.watch(simulator):
        trainer.fit(lit, train_dataloaders=loader)
    secs = max(timer.t1 - timer.t0, 1e-9)
    gflops = step_flops(simulator, [], graphs.sizes[timer.first_graph :]) / secs / 1e9
    out = {
        "pairs_per_s": timer.pairs / secs,
        "nodes_per_s": timer.nodes / secs,
        "steps_timed": timer.steps,
        "batch_size": int(c.batch_size),
        "mean_nodes_per_pair": timer.nodes / max(timer.pairs, 1),
        "seconds": secs,
        "gflops": gflops,
        "share_of_matmul": gflops / matmul,
    }
    print(
        f"training: {out['pairs_per_s']:.0f} pairs/s, {out['nodes_per_s']:.0f} nodes/s, "
        f"{gflops:.1f} GFLOP/s ({out['share_of_matmul']:.0%} of matmul)",
        flush=True,
    )
    return out


def activity_rows(cfg: DictConfig, runs: dict, source: Source, rng) -> list[dict]:
    """The trained model's (``source``) ms per frame for idle spheres, contacts and walls (one
    row per case), all timed together (:func:`physgnn.benchmark.learned.time_cases`)."""
    a = cfg.activity
    sim = source.simulator()
    base = runs[a.n_spheres]["traj"]
    engine = OmegaConf.to_container(cfg.engine)
    n_frames = sim.H + a.sleep_k + a.frames + 1
    mixed = simulate(resting_scene(cfg.scene, a.resting, a.moving, rng, n_frames), engine)
    mixed_states = frame_states(mixed, sim.H)
    sleeper = SleepingSimulator(sim, k=a.sleep_k)
    for s in mixed_states[: a.sleep_k + 1]:
        sleeper(s)
    asleep = int(sleeper.asleep.sum())
    n_all = a.resting + a.moving
    mix = f"{a.resting} resting + {a.moving} moving"
    cases = [
        ("contacts on", sim, base),
        ("contacts off (no sphere_contact)", sim, with_effects(base, sphere_contact=False)),
        ("walls", sim, base),
        ("no walls (ground only)", sim, without_walls(base)),
        (f"{mix}, sleeping on ({asleep} asleep)", sleeper, mixed_states[a.sleep_k + 1 :]),
        (f"{mix}, sleeping off", sim, mixed_states),
        (f"{n_all} moving", sim, bench_run(cfg, n_all, rng)),
    ]
    timed = [(s, x if isinstance(x, list) else frame_states(x, sim.H)) for _, s, x in cases]
    rows = []
    for (label, _, _), (_, states), t in zip(
        cases, timed, time_cases(timed, a.rounds), strict=True
    ):
        rows.append({"case": label, "n_spheres": int(states[0].pos.shape[0]), **_brief(t)})
        print(f"activity {label:45s}: {t['total_ms']:8.2f} ms/frame", flush=True)
    return rows


def rollout_rows(cfg: DictConfig, runs: dict, source: Source) -> list[dict]:
    """The trained model (``source``) through :func:`physgnn.rollout.rollout` (the path ``make
    eval`` times) on the bench scenes of ``rollout_sizes``: FPS and ms per frame of each
    part."""
    sim = source.simulator()
    rows = []
    for n in cfg.rollout_sizes:
        traj = runs[n]["traj"]
        rollout(sim, [traj], n_frames=sim.H + 2)  # warm-up
        timer = StepTimer()
        [res] = rollout(sim, [traj], n_frames=traj.n_frames, timer=timer)
        t = timer.timings
        steps = max(t["steps"], 1)
        ms = {k: 1000 * t[k] / steps for k in ("graph", "network", "integration", "total")}
        rows.append(
            {
                "n_spheres": n,
                "frames": steps,
                "fps": res.fps,
                **{f"{k}_ms": v for k, v in ms.items()},
            }
        )
        print(f"rollout n={n:6d}: {res.fps:8.2f} FPS", flush=True)
    return rows


def _brief(t: dict) -> dict:
    return {
        k: t[k]
        for k in (
            "total_ms",
            "graph_ms",
            "network_ms",
            "integrate_ms",
            "pp_edges",
            "ps_edges",
            "nodes",
        )
    }
