"""The stacked-table data path gives exactly what the per-pair path gave: the same batches
(every field, value and order) for the same seed, and the same losses of a short training.

The reference is the assembly the data module used before: one ``SceneState`` per pair
(``TrajectoryFrames.state``), collated by the PyG DataLoader (``Batch.from_data_list``).
"""

from __future__ import annotations

import functools

import lightning as L
import pytest
import torch
from lightning.pytorch.callbacks import Callback, ModelCheckpoint
from simdata import learned, trajectory
from torch.testing import assert_close
from torch_geometric.loader import DataLoader as PygLoader

from physgnn.data.dataset import read_split, write_split
from physgnn.data.pairs import EpochSampler, PairDataset
from physgnn.data.state import TrajectoryFrames
from physgnn.data.stats import compute_stats, write_stats
from physgnn.physics.scene import Effects
from physgnn.training.datamodule import StatePairDataModule
from physgnn.training.lit import LitSimulator
from physgnn.training.recipe import InputNoise, PushForward


class PerPairReference(torch.utils.data.Dataset):
    """The former assembly: item k is the ``SceneState`` of pair k, built on its own."""

    def __init__(self, trajectories: list, H: int, future: int = 0):
        self.frames = [TrajectoryFrames(t) for t in trajectories]
        self.H, self.future = H, future
        self.pairs = [
            (i, t) for i, f in enumerate(self.frames) for t in range(H, f.n_frames - 1 - future)
        ]

    def __len__(self) -> int:
        return len(self.pairs)

    def __getitem__(self, k: int):
        i, t = self.pairs[k]
        return self.frames[i].state(t, self.H, self.future)


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("exact") / "hand"
    train = [trajectory(2, frames=8, seed=0), trajectory(4, frames=10, seed=1)]
    train.append(trajectory(1, frames=7, seed=2, effects=Effects(rotation=False)))
    write_split(root / "train.h5", train, {"split": "train", "preset": "hand"})
    write_split(root / "val.h5", [trajectory(3, frames=9, seed=5)], {"split": "val"})
    write_stats(root, compute_stats(train))
    return root


def module(data_dir, seed: int, future: int) -> StatePairDataModule:
    return StatePairDataModule(
        str(data_dir),
        "hand",
        H=2,
        batch_size=4,
        pairs_per_epoch=10,
        val_pairs=5,
        seed=seed,
        pushforward_steps=future,
    )


def reference_loaders(data_dir, seed: int, future: int) -> tuple[PygLoader, PygLoader]:
    """The former train and validation loaders of ``module(data_dir, seed, future)``."""
    train = PerPairReference(read_split(data_dir / "train.h5"), 2, future)
    val = PerPairReference(read_split(data_dir / "val.h5"), 2)
    index = torch.randperm(len(val), generator=torch.Generator().manual_seed(1))[:5]  # val_seed 0
    subset = torch.utils.data.Subset(val, index.sort().values.tolist())
    sampler = EpochSampler(len(train), 10, seed)
    return PygLoader(train, batch_size=4, sampler=sampler), PygLoader(subset, batch_size=4)


def assert_same_batch(new, old) -> None:
    spheres, planes = new.host_sizes  # the layout kept on the host: the reference's sizes
    assert list(spheres) == old.ptr.diff().tolist()
    assert list(planes) == torch.bincount(old.plane_batch, minlength=old.num_graphs).tolist()
    assert sorted(k for k in new.keys() if k != "host_sizes") == sorted(old.keys())
    for key in old.keys():
        assert new[key].dtype == old[key].dtype, key
        assert torch.equal(new[key], old[key]), key
    assert new.num_graphs == old.num_graphs and new.num_nodes == old.num_nodes


@pytest.mark.parametrize("seed, future", [(0, 0), (3, 2)])
def test_batches_equal_the_per_pair_assembly(data_dir, seed, future):
    dm = module(data_dir, seed, future)
    old_train, old_val = reference_loaders(data_dir, seed, future)
    new_train = dm.train_dataloader()
    for _ in range(2):  # epochs 0 and 1 (each pass over a sampler moves to the next epoch)
        pairs = list(zip(new_train, old_train, strict=True))
        assert len(pairs) == 3
        for new, old in pairs:
            assert_same_batch(new, old)
    for new, old in zip(dm.val_dataloader(), old_val, strict=True):
        assert_same_batch(new, old)


def test_one_pair_is_a_batch_of_one():
    trajs = [trajectory(2, frames=8, seed=0), trajectory(3, frames=6, seed=1)]
    state = PairDataset(trajs, H=1, future=1)[7]  # trajectory 1, t = 2
    old = PerPairReference(trajs, 1, 1)[7]
    assert state.num_graphs == 1
    for key in old.keys():
        assert torch.equal(state[key], old[key]), key


class Losses(Callback):
    def __init__(self):
        self.train, self.val = [], []

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
        self.train.append(outputs["loss"].detach().clone())

    def on_validation_epoch_end(self, trainer, pl_module):
        self.val.append(trainer.callback_metrics["val/loss"].clone())


def short_training(fit) -> tuple[Losses, dict]:
    """Two epochs with noise and push-forward from the first step; ``fit(trainer, lit)``."""
    torch.manual_seed(0)
    simulator = learned(H=2, M=2, hidden=16)
    adam = functools.partial(torch.optim.Adam, lr=1e-2)
    lit = LitSimulator(
        simulator, adam, seed=3, noise=InputNoise(std=0.05), pushforward=PushForward(steps=2)
    )
    losses = Losses()
    trainer = L.Trainer(
        max_epochs=2,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        deterministic=True,
        num_sanity_val_steps=0,
        callbacks=[losses],
    )
    fit(trainer, lit)
    return losses, simulator.state_dict()


def test_short_training_losses_equal_the_per_pair_path(data_dir):
    dm = module(data_dir, 3, 2)
    new, new_weights = short_training(lambda trainer, lit: trainer.fit(lit, datamodule=dm))
    train, val = reference_loaders(data_dir, 3, 2)
    old, old_weights = short_training(lambda trainer, lit: trainer.fit(lit, train, val))
    assert len(new.train) == len(old.train) == 6 and len(new.val) == 2
    assert_close(torch.stack(new.train), torch.stack(old.train), rtol=1e-6, atol=1e-7)
    assert_close(torch.stack(new.val), torch.stack(old.val), rtol=1e-6, atol=1e-7)
    for key, value in old_weights.items():
        assert_close(new_weights[key], value, rtol=1e-6, atol=1e-7)


def test_a_run_resumed_mid_epoch_equals_a_straight_one(data_dir, tmp_path):
    """A checkpoint after 4 of 6 steps (epoch 1 of 3 batches, one batch done), resumed: the
    same batches, noise and weights as the straight run."""
    straight, straight_weights = short_training(
        lambda trainer, lit: trainer.fit(lit, datamodule=module(data_dir, 3, 2))
    )
    saver = ModelCheckpoint(dirpath=tmp_path, every_n_train_steps=4, save_top_k=-1)

    def with_saver(trainer, lit):
        trainer.callbacks.append(saver)
        trainer.fit(lit, datamodule=module(data_dir, 3, 2))

    short_training(with_saver)
    [mid] = list(tmp_path.glob("*step=4.ckpt"))
    resumed, resumed_weights = short_training(
        lambda trainer, lit: trainer.fit(lit, datamodule=module(data_dir, 3, 2), ckpt_path=mid)
    )
    assert len(resumed.train) == 2
    assert_close(torch.stack(resumed.train), torch.stack(straight.train[4:]))
    for key, value in straight_weights.items():
        assert_close(resumed_weights[key], value)
