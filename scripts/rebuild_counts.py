"""How often the rebuild passes of a learned step add edges (docs/MODEL.md, "Contacts within the
frame"), over the scene-frames of a dataset split.

    python scripts/rebuild_counts.py outputs/data/small/train.h5 [--every 5] [--run RUN]

Without ``--run`` the passes are an oracle's, a perfect network under the gating: every sphere
in reach takes the truth's next velocity, the rest fly ballistically. With ``--run`` (a run
folder or ``pretrained``) they are that model's own. Prints the scene-frames, the share whose
first rebuild added edges, the histogram of rebuilds that added edges (0, 1, 2, ... up to the
model's ``contact_passes``, and how many still grew at the bound), and the edges the rebuilds
added against the first build's.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import torch
from torch_geometric.data import Batch

from physgnn.data.dataset import read_split
from physgnn.data.state import TrajectoryFrames
from physgnn.graph.rules import ballistic_velocity
from physgnn.models.learned import LearnedSimulator


def oracle_head(sim: LearnedSimulator):
    """A head whose spheres in reach take the truth's next velocity (``state.target_vel``)."""

    def head(state, graph, provisional=()):
        reach = sim.reach(state, graph, provisional).spheres
        vel = torch.where(reach[:, None], state.target_vel, ballistic_velocity(state))
        return vel, state.angvel[:, 0]

    return head


def passes(sim: LearnedSimulator, state, bound: int) -> tuple[int, bool, int, int]:
    """``(rebuilds that added edges, still growing at the bound, first edges, last edges)`` of
    one step: :meth:`LearnedSimulator.predict`'s loop, counted."""
    graph = sim.graph_builder(state)
    first = graph.pp_index.shape[1] + graph.ps_index.shape[1]
    vel, _ = sim.head(state, graph)
    provisional, grown = [], 0
    for _ in range(bound + 1):
        provisional.append(vel)
        wider = sim.graph_builder(state, provisional)
        if not wider.grew(graph):
            return grown, False, first, graph.pp_index.shape[1] + graph.ps_index.shape[1]
        if grown == bound:
            break
        grown, graph = grown + 1, wider
        vel, _ = sim.head(state, graph, tuple(provisional))
    return grown, True, first, graph.pp_index.shape[1] + graph.ps_index.shape[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("split")
    parser.add_argument("--every", type=int, default=5, help="every k-th frame")
    parser.add_argument("--run", default=None, help="a run folder or 'pretrained'")
    args = parser.parse_args()
    if args.run is None:  # the dataset's statistics: the oracle's network never runs
        sim = LearnedSimulator(json.loads((Path(args.split).parent / "stats.json").read_text()))
        sim.head = oracle_head(sim)
    else:
        from physgnn.training.runs import load_run

        sim = load_run(args.run)[0]
    sim.eval()
    counts, at_bound, first_total, last_total, frames = Counter(), 0, 0, 0, 0
    with torch.no_grad():
        for traj in read_split(args.split):
            source = TrajectoryFrames(traj)
            for t in range(sim.H, traj.n_frames - 1, args.every):
                state = Batch.from_data_list([source.state(t, sim.H, future=1)])
                grown, bound, first, last = passes(sim, state, sim.contacts.contact_passes)
                counts[grown] += 1
                at_bound += bound
                first_total, last_total, frames = first_total + first, last_total + last, frames + 1
    added = sum(v for k, v in counts.items() if k > 0)
    print(f"{frames} scene-frames of {args.split} (every {args.every}th frame)")
    print(f"a rebuild added edges in {added} ({100 * added / max(frames, 1):.1f} %)")
    print("rebuilds that added edges: " + ", ".join(f"{k}: {counts[k]}" for k in sorted(counts)))
    print(f"still growing at the bound ({sim.contacts.contact_passes} rebuilds): {at_bound}")
    growth = 100 * (last_total / max(first_total, 1) - 1)
    print(
        f"edges: {last_total} after the rebuilds against {first_total} at the first build "
        f"(+{growth:.2f} %)"
    )


if __name__ == "__main__":
    main()
