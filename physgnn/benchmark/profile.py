"""Where the time of one training step goes (``make bench``).

One step of the baseline's training, as :class:`~physgnn.training.lit.LitSimulator` runs it,
split into: data assembly (the loader's next batch), input noise, push-forward (its network
steps, without their graph building), graph building (every graph the step builds, timed by a
:class:`~physgnn.models.profiling.StepTimer` watching the simulator), forward (the loss of the
batch, without its graph building), backward, and optimiser (gradient clipping and the Adam
step). The rollout frame's parts are the rollout table's (``activity.rollout_rows``).
"""

from __future__ import annotations

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig

from physgnn.data.pairs import EpochSampler, PairDataset, pair_loader
from physgnn.models.profiling import StepTimer
from physgnn.training.lit import push_forward
from physgnn.training.noise import add_noise

PARTS = ("data", "noise", "push_forward", "graph", "forward", "backward", "optimiser")


def forward_flops(simulator, sizes: list[tuple[int, int, int]]) -> int:
    """FLOPs of one network call on each graph of ``sizes`` ``(nodes, pp edges, ps edges)``."""
    return sum(simulator.network.flops_per_step(*size) for size in sizes)


def step_flops(simulator, pushed: list, loss: list) -> int:
    """FLOPs of a training step: push-forward graphs once, loss graphs 3 times (module doc)."""
    return forward_flops(simulator, pushed) + 3 * forward_flops(simulator, loss)


def training_profile(cfg: DictConfig, trajectories: list, stats: dict, matmul: float) -> dict:
    """ms per part of a training step (mean over ``profile.steps`` after the warm-up), their
    shares of the step, pairs and nodes per second, and the step's FLOP rate (GFLOP/s and
    share of the ``matmul`` rate in GFLOP/s)."""
    c = cfg.profile
    simulator = instantiate(cfg.model, stats=stats)
    lit = instantiate(cfg.training.lit, simulator=simulator)
    optimizer = lit.optimizer_factory(simulator.parameters())
    data = PairDataset(trajectories, simulator.H, future=int(c.pushforward))
    total_steps = int(c.warmup_steps + c.steps)
    sampler = EpochSampler(len(data), total_steps * int(c.batch_size), int(cfg.seed))
    batches = iter(pair_loader(data, int(c.batch_size), sampler))
    seconds, pairs, nodes, flops = dict.fromkeys(PARTS, 0.0), 0, 0, 0
    timer = StepTimer()
    with timer.watch(simulator):
        for step in range(total_steps):
            parts, batch, step_flop = _one_step(lit, optimizer, batches, timer, step, c)
            if step >= c.warmup_steps:
                seconds = {k: seconds[k] + parts[k] for k in PARTS}
                pairs, nodes = pairs + batch.num_graphs, nodes + batch.num_nodes
                flops += step_flop
    total = max(sum(seconds.values()), 1e-12)
    out = {f"{k}_ms": 1000 * seconds[k] / c.steps for k in PARTS}
    out |= {f"{k}_share": seconds[k] / total for k in PARTS}
    out |= {"step_ms": 1000 * total / c.steps, "pairs_per_s": pairs / total}
    out |= {"nodes_per_s": nodes / total, "steps": int(c.steps), "batch_size": int(c.batch_size)}
    out["pushforward_steps"] = int(c.pushforward)
    out |= {"gflop_per_step": flops / c.steps / 1e9, "gflops": flops / total / 1e9}
    out["share_of_matmul"] = out["gflops"] / matmul
    print(
        f"profile: {out['step_ms']:.1f} ms per training step: "
        + ", ".join(f"{k} {out[f'{k}_ms']:.1f}" for k in PARTS)
        + f"; {out['gflops']:.1f} GFLOP/s ({out['share_of_matmul']:.0%} of matmul)",
        flush=True,
    )
    return out


def _one_step(lit, optimizer, batches, timer: StepTimer, step: int, c) -> tuple[dict, object, int]:
    """One training step: seconds per part, the batch and the step's FLOPs (module doc)."""
    simulator = lit.simulator
    device = next(simulator.parameters()).device
    generator = torch.Generator(device=device).manual_seed(step)
    marks = [(timer.clock(device), timer.graph, len(timer.sizes))]

    def mark():
        marks.append((timer.clock(device), timer.graph, len(timer.sizes)))

    batch = next(batches).to(device)
    mark()
    batch = add_noise(batch, simulator, lit.noise.std, generator)
    mark()
    batch = push_forward(batch, simulator, int(c.pushforward))
    mark()
    loss = lit.losses(batch)["loss"]
    mark()
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    mark()
    torch.nn.utils.clip_grad_norm_(simulator.parameters(), float(c.gradient_clip_val))
    optimizer.step()
    mark()
    spans = [(b[0] - a[0], b[1] - a[1]) for a, b in zip(marks, marks[1:], strict=False)]
    (data, _), (noise, _), (pushed, pushed_graph), (forward, forward_graph) = spans[:4]
    parts = {"data": data, "noise": noise, "push_forward": pushed - pushed_graph}
    parts |= {"graph": pushed_graph + forward_graph, "forward": forward - forward_graph}
    parts |= {"backward": spans[4][0], "optimiser": spans[5][0]}
    graph_counts = [m[2] for m in marks]  # after: data, noise, push-forward, forward, ...
    pushed = timer.sizes[graph_counts[2] : graph_counts[3]]
    loss = timer.sizes[graph_counts[3] : graph_counts[4]]
    return parts, batch, step_flops(simulator, pushed, loss)
