"""StatePairDataModule on hand-built trajectories written with dataset.write_split."""

from __future__ import annotations

import pytest
import torch
from simdata import trajectory
from torch.testing import assert_close

from physgnn.data.dataset import DatasetError, write_split
from physgnn.data.stats import compute_stats, write_stats
from physgnn.physics.scene import EFFECT_NAMES, Effects
from physgnn.training.datamodule import PairDataset, StatePairDataModule


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("data") / "hand"
    train = [trajectory(2, frames=8, seed=0), trajectory(3, frames=10, seed=1)]
    train.append(trajectory(1, frames=6, seed=2, effects=Effects(rotation=False, friction=False)))
    write_split(root / "train.h5", train, {"split": "train", "preset": "hand"})
    write_split(root / "val.h5", [trajectory(2, frames=9, seed=5)], {"split": "val"})
    write_stats(root, compute_stats(train))
    return root


def make(data_dir, **kwargs) -> StatePairDataModule:
    args = dict(data_dir=str(data_dir), preset="hand", H=2, batch_size=4, pairs_per_epoch=10)
    return StatePairDataModule(**(args | kwargs))


def test_pairs_cover_exactly_frames_H_to_T_minus_2():
    trajs = [trajectory(2, frames=8, seed=0), trajectory(1, frames=5, seed=1)]
    pairs = PairDataset(trajs, H=2)
    expected = [[0, t] for t in range(2, 7)] + [[1, t] for t in range(2, 4)]
    assert pairs.pairs.tolist() == expected
    state = pairs[3]  # trajectory 0, t = 5
    assert state.vel.shape == (2, 3, 3)
    assert_close(state.pos, torch.as_tensor(trajs[0].pos[5]))
    assert_close(state.target_vel, torch.as_tensor((trajs[0].pos[6] - trajs[0].pos[5]) / 0.1))


def test_missing_dataset_names_the_command(tmp_path):
    dm = StatePairDataModule(data_dir=str(tmp_path / "nothing"), preset="tiny")
    with pytest.raises(DatasetError) as info:
        dm.stats()
    message = str(info.value)  # the folder is not the preset's own: data.dir= says where
    assert f"`python -m physgnn.generate data=tiny data.dir={tmp_path / 'nothing'}`" in message
    assert "make data" not in message and "\n" not in message


def test_epoch_size_batch_size_and_seeded_stream(data_dir):
    batches = list(make(data_dir, seed=3).train_dataloader())
    assert [b.num_graphs for b in batches] == [4, 4, 2]
    again = list(make(data_dir, seed=3).train_dataloader())
    other = list(make(data_dir, seed=4).train_dataloader())
    for a, b in zip(batches, again, strict=True):
        assert torch.equal(a.pos, b.pos) and torch.equal(a.vel, b.vel)
    assert not all(
        a.pos.shape == b.pos.shape and torch.equal(a.pos, b.pos)
        for a, b in zip(batches, other, strict=True)
    )


def test_workers_give_the_same_stream(data_dir):
    plain = list(make(data_dir, seed=1).train_dataloader())
    workers = list(make(data_dir, seed=1, num_workers=1).train_dataloader())
    for a, b in zip(plain, workers, strict=True):
        assert torch.equal(a.pos, b.pos) and torch.equal(a.target_vel, b.target_vel)


def test_validation_is_a_fixed_subset(data_dir):
    dm = make(data_dir, val_pairs=4)
    first = [b.pos for b in dm.val_dataloader()]
    second = [b.pos for b in dm.val_dataloader()]
    assert sum(p.shape[0] for p in first) == 4 * 2  # 4 states of 2 spheres
    for a, b in zip(first, second, strict=True):
        assert torch.equal(a, b)
    everything = make(data_dir, val_pairs=1000)
    assert sum(b.num_graphs for b in everything.val_dataloader()) == 9 - 1 - 2


def test_every_seed_validates_on_the_same_subset(data_dir):
    def val_states(**kw):
        return [b.pos for b in make(data_dir, val_pairs=3, **kw).val_dataloader()]

    for a, b in zip(val_states(seed=0), val_states(seed=5), strict=True):
        assert torch.equal(a, b)
    other = val_states(seed=0, val_seed=4)
    assert any(not torch.equal(a, b) for a, b in zip(val_states(seed=0), other, strict=True))


def test_effects_trained_is_the_union(data_dir):
    effects = make(data_dir).effects_trained()
    assert effects.tolist() == [True] * len(EFFECT_NAMES)


def test_stats_are_read(data_dir):
    stats = make(data_dir).stats()
    assert len(stats["delta_vel"]["std"]) == 3 and stats["n_pairs"] == 7 + 9 + 5


def test_sampler_is_seeded_by_epoch():
    from physgnn.data.pairs import EpochSampler

    sampler = EpochSampler(50, 20, seed=7)
    first, second = list(sampler), list(sampler)
    assert len(first) == 20 and all(0 <= i < 50 for i in first) and first != second
    sampler.set_epoch(1)
    assert list(sampler) == second  # epoch 1 is the same with or without set_epoch
    sampler.set_epoch(0)
    assert list(sampler) == first


def test_sampler_leaves_out_the_batches_a_resumed_epoch_gave():
    from physgnn.data.pairs import EpochSampler

    plain = EpochSampler(50, 20, seed=7)
    epochs = [list(plain), list(plain), list(plain)]
    done = {"batches": 0}
    sampler = EpochSampler(50, 20, seed=7, batch_size=6, batches_done=lambda: done["batches"])
    assert list(sampler) == epochs[0]  # a fresh run
    done["batches"] = 4 + 1  # 4 batches per epoch (20 pairs by 6): epoch 1 gave one batch
    sampler.set_epoch(1)
    assert list(sampler) == epochs[1][6:]
    done["batches"] = 8  # epoch 2 starts: nothing is left out
    assert list(sampler) == epochs[2]
