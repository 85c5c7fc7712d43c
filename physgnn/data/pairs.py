"""One-step state pairs ``(X_t, v_{t+1}, ω_{t+1})`` of trajectories, and the seeded sampler that
draws them (plain torch: the Lightning data module and the bench use them).

A *pair* is a frame ``t`` of a trajectory with ``t ∈ [H, T − 2]``: the state at ``t`` with
``H + 1`` velocities of history, and the finite-difference velocities of frame ``t + 1`` as
targets (:class:`physgnn.data.state.TrajectoryFrames`).
"""

from __future__ import annotations

import torch
from torch.utils.data import Dataset, Sampler

from physgnn.data.state import TrajectoryFrames


class PairDataset(Dataset):
    """Every valid ``(trajectory, t)`` pair of a list of trajectories; item = ``SceneState``.

    ``future`` = K > 0 adds the K + 1 next frames to each item (push-forward targets) and
    keeps only the frames ``t ≤ T − K − 2`` that have them."""

    def __init__(self, trajectories: list, H: int, future: int = 0):
        self.frames = [TrajectoryFrames(traj) for traj in trajectories]
        self.H, self.future = int(H), int(future)
        last = 1 + self.future
        pairs = [
            (i, t) for i, f in enumerate(self.frames) for t in range(self.H, f.n_frames - last)
        ]
        self.pairs = torch.tensor(pairs, dtype=torch.long).reshape(-1, 2)

    def __len__(self) -> int:
        return int(self.pairs.shape[0])

    def __getitem__(self, k: int):
        i, t = self.pairs[k].tolist()
        return self.frames[i].state(t, self.H, self.future)


class EpochSampler(Sampler):
    """``num_samples`` indices drawn uniformly with replacement from ``range(size)``, seeded by
    ``(seed, epoch)``: epoch k draws the same pairs whether training ran straight through or
    resumed from a checkpoint. Lightning calls ``set_epoch`` before each epoch; without it
    each iteration moves on to the next epoch.

    With ``world_size`` > 1 (DDP) process ``rank`` takes every ``world_size``-th index from
    the ``rank``-th (the draw cut to a multiple of ``world_size``): the processes' batches of a
    step together are the batch of one process with a ``world_size`` times larger batch."""

    def __init__(self, size: int, num_samples: int, seed: int, rank: int = 0, world_size: int = 1):
        self.size, self.num_samples, self.seed = int(size), int(num_samples), int(seed)
        self.rank, self.world_size = int(rank), int(world_size)
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.num_samples // self.world_size

    def __iter__(self):
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
        self.epoch += 1
        drawn = torch.randint(self.size, (self.num_samples,), generator=generator)
        yield from drawn[self.rank : len(self) * self.world_size : self.world_size].tolist()
