"""The bench's crossover alone, for one trained run at learned settings of your choice: ``python
scripts/crossover_settings.py RUN [--settings MAPPING] [--sizes 154 1000] [--out FILE]``.

``make bench``'s crossover phase (:func:`physgnn.benchmark.crossover.crossover`: ``draws``
random_box piles per size, each cut into its windows, every learned setting and pybullet at
``crossover.substeps`` taking turns, medians over the draws), without the bench's other phases.
The piles are drawn from the bench's seed at once, so they are not the piles of a whole ``make
bench`` (whose earlier phases draw first). ``--settings``: the learned settings as a YAML
mapping, replacing ``crossover.learned_settings`` (default: as trained, passes 0, and compiled
with passes 0, the fastest of the default model). Prints each size and window's points; with
``--out``, the crossover's dict as JSON.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch
import yaml

from physgnn.benchmark.crossover import crossover
from physgnn.benchmark.source import learned_source
from physgnn.cli.overrides import compose_config

FASTEST = (
    "{as_trained: {}, passes0: {contact_passes: 0},"
    " compiled_passes0: {compile: true, contact_passes: 0}}"
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a run folder or pretrained")
    parser.add_argument("--settings", default=FASTEST, help="learned settings, a YAML mapping")
    parser.add_argument("--sizes", nargs="+", type=int, default=[154, 1000])
    parser.add_argument("--out", help="write the crossover's dict here as JSON")
    args = parser.parse_args()
    settings = yaml.safe_load(args.settings)
    if not isinstance(settings, dict):
        raise SystemExit(f"error: --settings must be a mapping of name to knobs, got {settings!r}")
    cfg = compose_config(
        "bench",
        [
            f"run={args.run}",
            f"crossover.sizes=[{','.join(map(str, args.sizes))}]",
            "crossover.learned_settings=null",
            f"crossover.learned_settings={args.settings}",
        ],
    )
    torch.set_num_threads(int(cfg.threads))
    result = crossover(cfg, np.random.default_rng(int(cfg.seed)), learned_source(cfg, {}))
    for case in result["cases"]:
        load = f"load {case['loadavg_start']:.1f} → {case['loadavg_end']:.1f}"
        print(f"{case['n_spheres']} spheres, {case['window']} ({load}):")
        for point in case["points"]:
            mse, fps = point["mse20"], point["fps"]
            print(f"  {point['simulator']:28s} MSE20 {mse:.3g} at {fps:.3g} frames/s")
        print(f"  front: {', '.join(case['front'])}; matched: {case['matched_substeps']}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1, default=str)


if __name__ == "__main__":
    main()
