"""The cost of a rollout frame of trained models, side by side: ``python scripts/frame_cost.py
RUN RUN ... [--sizes 154 1000] [--rounds 5]``.

Each RUN (a run folder or ``pretrained``) rolls out over the same bench pile in motion
(``conf/bench.yaml``'s random_box at each size, the spheres landed as the crossover lands them,
then ``crossover.frames`` frames), one scene at a time on one thread, the runs taking turns for
``--rounds`` rounds. Printed per size: each run's median ms per frame, its ratio to the first
run's (the median of the rounds' ratios), the graph builds and network passes per frame, and the
1-minute load average before and after. A rebuild on a pass's velocities that keeps every
allowance reuses the last build's candidates; one that widens one counts as a whole build too.
"""

from __future__ import annotations

import argparse
import os
from collections import Counter
from statistics import median

import numpy as np
import torch

from physgnn.benchmark.crossover import truth_windows
from physgnn.cli.overrides import compose_config
from physgnn.graph.builder import GraphBuilder
from physgnn.rollout import rollout
from physgnn.training.runs import load_run


def counted_rollout(sim, window) -> tuple[float, Counter]:
    """``(ms per frame, {"builds", "rebuilds", "passes"} per rollout)`` of ``sim`` over
    ``window``: whole graph builds, rebuilds on a pass's velocities (``extend``, a whole build
    only where a velocity widens the reach) and network passes."""
    calls = Counter()
    originals = {
        (GraphBuilder, "build"): "builds",
        (GraphBuilder, "extend"): "rebuilds",
        (type(sim), "head"): "passes",
    }

    def counting(method, name):
        def call(self, *args, **kwargs):
            calls[name] += 1
            return method(self, *args, **kwargs)

        return call

    saved = {key: getattr(*key) for key in originals}
    for (owner, attr), name in originals.items():
        setattr(owner, attr, counting(saved[owner, attr], name))
    try:
        result = rollout(sim, [window])[0]
    finally:
        for (owner, attr), method in saved.items():
            setattr(owner, attr, method)
    return 1000.0 / result.fps, calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+")
    parser.add_argument("--sizes", nargs="+", type=int, default=[154, 1000])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = compose_config("bench", ["run=null"])
    sims = [load_run(run)[0].eval() for run in args.runs]
    rng = np.random.default_rng(int(cfg.seed))
    for n in args.sizes:
        window = truth_windows(cfg, n, rng, max(int(s.H) for s in sims), {})["landed"]
        frames = window.n_frames
        for sim in sims:
            rollout(sim, [window.truncated(sim.H + 3)])  # warm-up
        load = os.getloadavg()[0]
        ms = [[] for _ in sims]
        calls = [Counter() for _ in sims]
        for _ in range(args.rounds):
            for k, sim in enumerate(sims):
                cost, counted = counted_rollout(sim, window)
                ms[k].append(cost)
                calls[k] += counted
        print(f"{n} spheres, {frames} frames, load {load:.1f} -> {os.getloadavg()[0]:.1f}")
        for k, run in enumerate(args.runs):
            ratio = median(a / b for a, b in zip(ms[k], ms[0], strict=True))
            steps = args.rounds * (frames - sims[k].H - 1)
            builds, rebuilds, passes = (
                calls[k][name] / steps for name in ("builds", "rebuilds", "passes")
            )
            print(
                f"  {run}: {median(ms[k]):.1f} ms/frame, {ratio:.2f}x the first; whole builds "
                f"{builds:.2f}, rebuilds {rebuilds:.2f}, passes {passes:.2f} per frame"
            )


if __name__ == "__main__":
    main()
