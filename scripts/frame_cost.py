"""The cost of a rollout frame of trained models, side by side: ``python scripts/frame_cost.py
RUN RUN ... [--sizes 154 1000] [--rounds 5] [--parts] [--whole-passes]``.

Each RUN (a run folder or ``pretrained``) rolls out over the same bench pile in motion
(``conf/bench.yaml``'s random_box at each size, the spheres landed as the crossover lands them,
then ``crossover.frames`` frames), one scene at a time on one thread, the runs taking turns for
``--rounds`` rounds. Printed per size: each run's median ms per frame, its ratio to the first
run's (the median of the rounds' ratios), the graph builds and network passes per frame, and the
1-minute load average before and after. A rebuild on a pass's velocities that keeps every
allowance reuses the last build's candidates; one that widens one searches pairs for the grown
spheres only (a whole build only off the CPU's k-d tree, where it counts as one).

``--parts`` also splits each run's frame into its parts, ms per frame over all rounds: builds,
rebuilds (``extend``, a whole build within it counted here), the first network pass of the frame
(``head``), the later passes, the network within the passes, and the rest (integration,
bookkeeping). ``--whole-passes`` measures each run a second time, in the same rounds, with
``model.contacts.incremental_passes=false`` (every pass a whole pass: the cost before passes
reused their latents).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from collections import Counter
from statistics import median

import numpy as np
import torch

from physgnn.benchmark.crossover import truth_windows
from physgnn.cli.overrides import compose_config
from physgnn.graph.builder import GraphBuilder
from physgnn.models import passes
from physgnn.rollout import rollout
from physgnn.training.runs import load_run

PARTS = ("build", "rebuilds", "first pass", "later passes", "network", "rest")


def counted_rollout(sim, window) -> tuple[float, Counter, Counter]:
    """``(ms per frame, {"builds", "rebuilds", "passes"} per rollout, seconds per part)`` of
    ``sim`` over ``window``: whole graph builds, rebuilds on a pass's velocities (``extend``, a
    whole build only where a velocity widens the reach) and network passes; the seconds of
    :data:`PARTS` but the rest (a call within another timed one counts in the outer one)."""
    calls, seconds, inside = Counter(), Counter(), []
    originals = {
        (GraphBuilder, "build"): "builds",
        (GraphBuilder, "extend"): "rebuilds",
        (type(sim), "head"): "passes",
    }

    def counting(method, name):
        def call(self, *args, **kwargs):
            calls[name] += 1
            part = {"builds": "build", "rebuilds": "rebuilds"}.get(name)
            if name == "passes":
                part = "later passes" if calls["frame passes"] else "first pass"
                calls["frame passes"] += 1
            inside.append(part)
            t0 = time.perf_counter()
            try:
                return method(self, *args, **kwargs)
            finally:
                inside.pop()
                if not inside:
                    seconds[part] += time.perf_counter() - t0

        return call

    def framing(predict):
        def call(self, state):
            calls["frame passes"] = 0
            return predict(self, state)

        return call

    def timed_network(network_call):
        def call(*args):
            run = network_call(*args)

            def timed(*inputs):
                t0 = time.perf_counter()
                out = run(*inputs)
                seconds["network"] += time.perf_counter() - t0
                return out

            return timed

        return call

    saved = {key: getattr(*key) for key in originals}
    saved |= {(type(sim), "predict_motion"): type(sim).predict_motion}
    saved |= {(passes, "network_call"): passes.network_call}
    for (owner, attr), name in originals.items():
        setattr(owner, attr, counting(saved[owner, attr], name))
    type(sim).predict_motion = framing(saved[type(sim), "predict_motion"])
    passes.network_call = timed_network(saved[passes, "network_call"])
    try:
        t0 = time.perf_counter()
        result = rollout(sim, [window])[0]
        seconds["total"] = time.perf_counter() - t0
    finally:
        for (owner, attr), method in saved.items():
            setattr(owner, attr, method)
    del calls["frame passes"]
    return 1000.0 / result.fps, calls, seconds


def parts_line(seconds: Counter, steps: int) -> str:
    """ms per frame of each of :data:`PARTS` (the rest: the total less the others but the
    network, which is within the passes)."""
    ms = {part: 1000.0 * seconds[part] / steps for part in PARTS[:-1]}
    ms["rest"] = 1000.0 * seconds["total"] / steps - sum(
        ms[part] for part in ("build", "rebuilds", "first pass", "later passes")
    )
    return ", ".join(f"{part} {ms[part]:.2f}" for part in PARTS)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+")
    parser.add_argument("--sizes", nargs="+", type=int, default=[154, 1000])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--parts", action="store_true", help="split each frame by part")
    parser.add_argument("--whole-passes", action="store_true", help="each run also without reuse")
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = compose_config("bench", ["run=null"])
    runs = []  # (name, simulator, its contact options while measured)
    for run in args.runs:
        sim = load_run(run)[0].eval()
        runs.append((run, sim, sim.contacts))
        if args.whole_passes:
            whole = dataclasses.replace(sim.contacts, incremental_passes=False)
            runs.append((f"{run} (whole passes)", sim, whole))
    rng = np.random.default_rng(int(cfg.seed))
    for n in args.sizes:
        history = max(int(sim.H) for _, sim, _ in runs)
        window = truth_windows(cfg, n, rng, history, {})["landed"]
        measure(runs, window, n, args)


def measure(runs: list, window, n: int, args) -> None:
    """Time ``runs`` over ``window`` in ``args.rounds`` interleaved rounds and print them
    (module doc)."""
    frames = window.n_frames
    for _, sim, contacts in runs:
        sim.contacts = contacts
        rollout(sim, [window.truncated(sim.H + 3)])  # warm-up
    load = os.getloadavg()[0]
    ms = [[] for _ in runs]
    calls = [Counter() for _ in runs]
    seconds = [Counter() for _ in runs]
    for _ in range(args.rounds):
        for k, (_, sim, contacts) in enumerate(runs):
            sim.contacts = contacts
            cost, counted, timed = counted_rollout(sim, window)
            ms[k].append(cost)
            calls[k] += counted
            seconds[k] += timed
    print(f"{n} spheres, {frames} frames, load {load:.1f} -> {os.getloadavg()[0]:.1f}")
    for k, (run, sim, _) in enumerate(runs):
        ratio = median(a / b for a, b in zip(ms[k], ms[0], strict=True))
        steps = args.rounds * (frames - sim.H - 1)
        builds, rebuilds, passes = (
            calls[k][name] / steps for name in ("builds", "rebuilds", "passes")
        )
        print(
            f"  {run}: {median(ms[k]):.1f} ms/frame, {ratio:.2f}x the first; whole builds "
            f"{builds:.2f}, rebuilds {rebuilds:.2f}, passes {passes:.2f} per frame"
        )
        if args.parts:
            print(f"    ms per frame: {parts_line(seconds[k], steps)}")


if __name__ == "__main__":
    main()
