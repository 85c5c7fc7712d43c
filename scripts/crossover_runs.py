"""The bench's crossover for several trained models on the same draws of landed piles: ``python
scripts/crossover_runs.py RUN RUN ... [--sizes 154 1000]``.

Each size draws one ``conf/bench.yaml`` random_box pile, the sizes one after another from the
bench's seed (not the draws of a whole ``make bench``, whose earlier phases draw first), and
lands it. Every RUN (a run folder or ``pretrained``) then takes its turns against pybullet at
``crossover.substeps`` on its landed window (the crossover's rounds, one scene at a time, one
thread). Printed per size and run: MSE20 and median frames/s of the learned model and
of each setting, the median learned-over-pybullet ratio, whether the model is on the MSE20
front and its matched setting.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
import torch

from physgnn.benchmark.crossover import as_loaded, taking_turns, truth_windows
from physgnn.benchmark.crossover_summary import judged, summary
from physgnn.cli.overrides import compose_config
from physgnn.training.runs import load_run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="run folders or pretrained")
    parser.add_argument("--sizes", nargs="+", type=int, default=[154, 1000])
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = compose_config("bench")
    sims = {run: load_run(run)[0].eval() for run in args.runs}
    histories = {int(sim.H) for sim in sims.values()}
    if len(histories) != 1:
        raise SystemExit(f"error: the runs have different histories H {sorted(histories)}")
    H = histories.pop()
    rng = np.random.default_rng(cfg.seed)
    for n in args.sizes:
        window = truth_windows(cfg, n, rng, H, {})["landed"]
        for run, sim in sims.items():
            start = os.getloadavg()[0]
            c = cfg.crossover
            rows = taking_turns([as_loaded(run, sim, 1)], window, {}, list(c.substeps), c.rounds)
            size = judged(summary([rows]))
            print(f"{n} spheres, {run} (load {start:.1f} → {os.getloadavg()[0]:.1f}):")
            for r in rows:
                ratio = "" if r["ratio"] is None else f", learned / it {r['ratio']:.3g}×"
                speed = f"{r['fps']:.3g} frames/s{ratio}"
                print(f"  {r['simulator']:12s} MSE20 {r['mse20']:.3g} at {speed}")
            matched = size["matched_substeps"]
            ratio = (
                "none as accurate"
                if matched is None
                else (f"{matched} substeps, learned / it {size['matched_ratio']:.3g}×")
            )
            print(f"  on the MSE20 front: {size['on_front']}; matched: {ratio}", flush=True)


if __name__ == "__main__":
    main()
