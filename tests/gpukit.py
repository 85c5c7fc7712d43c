"""Shared by the GPU-readiness tests (host round trips, fixed capacity, compiled regions, the
fake accelerator, the bench): the sync and op budgets and a training batch of the tiny
preset."""

from __future__ import annotations

import torch

from physgnn.data.pairs import PairDataset

# the budget of a training step: graph builds (contact noise, the push-forward's passes, the
# loss), finiteness; k is drawn on the host
TRAIN_STEP_SYNCS = 7
# the graph builds of a frame (one, plus a rebuild per pass that adds edges, at most
# model.contacts.contact_passes) and the divergence test
ROLLOUT_FRAME_SYNCS = 4
# the budget of aten ops a compiled training step dispatches outside its compiled regions
OPS_PER_TRAINING_STEP = 1500


def training_batch(trajectories, H: int):
    """About 32 state pairs of the tiny preset's training split, spread over it."""
    pairs = PairDataset(trajectories, H, future=2)
    return pairs.batch(torch.arange(0, len(pairs), max(len(pairs) // 32, 1)))
