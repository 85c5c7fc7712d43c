"""Host round trips: the counter, sync-free candidates and compaction, one read-back per graph
build, and the sync budgets of a training step and a rollout frame."""

from __future__ import annotations

import json

import pytest
import torch
from gpukit import ROLLOUT_FRAME_SYNCS, TRAIN_STEP_SYNCS
from handmade import make_state, random_batch
from hydra.utils import instantiate
from omegaconf import OmegaConf
from torch.testing import assert_close

import physgnn.graph.builder as builder_module
from physgnn.benchmark.gpu_readiness import rollout_frame_counts, training_step_counts
from physgnn.benchmark.syncs import counting
from physgnn.cli import compose_config
from physgnn.data.dataset import read_split
from physgnn.data.pairs import PairDataset
from physgnn.graph.builder import GraphBuilder
from physgnn.graph.candidates import compact, scene_counts, scene_pairs, scene_plane_pairs
from physgnn.rollout import rollout
from physgnn.training.finite import FINITE_CHECK_EVERY, FiniteWatch, NonFiniteLossError


def test_the_counter_sees_each_kind_of_read_back():
    x, repeats = torch.arange(6.0), torch.tensor([1, 0, 2, 1, 0, 1])
    with counting() as c:
        x.sum().item()
        torch.nonzero(x > 2)
        x[x > 2]
        torch.repeat_interleave(x, repeats)
        x.tolist()
        bool(x.any())
    assert c.syncs == 6 and c.copies == 0
    with counting() as c:
        torch.repeat_interleave(x, repeats, output_size=5)
        x[torch.arange(2)]
        torch.where(x > 2, x, 0.0).cumsum(0)
        x * torch.tensor(2.0)  # a 0-dim host scalar is a kernel argument, no copy
    assert c.syncs == 0 and c.kernels > 0


def test_the_counter_sees_each_host_to_device_copy_once():
    x = torch.zeros(3, device="meta")
    with counting() as c:
        torch.tensor([1, 2, 3])  # host data made a tensor: a copy where the device is a GPU
        x.new_tensor([1.0, 2.0]).numel()  # on meta nothing is dispatched: not seen here
        torch.ones(3).to("meta")  # a CPU tensor copied to another device
        torch.ones(()).to("meta")
        x.copy_(torch.ones(3))
        torch.ones(3).to("meta", non_blocking=True)  # does not wait
    assert c.copies == c.syncs == 4


def test_scene_pairs_are_every_same_scene_pair_in_order():
    sizes = (3, 1, 0, 4)
    scene = torch.repeat_interleave(torch.arange(4), torch.tensor(sizes))
    i, j = scene_pairs(sizes, scene, scene_counts(scene, len(sizes)))
    brute = [(a, b) for a in range(8) for b in range(a + 1, 8) if scene[a] == scene[b]]
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == brute


def test_scene_plane_pairs_pair_each_plane_with_its_scene():
    spheres, planes = (2, 3), (1, 2)
    scene = torch.tensor([0, 0, 1, 1, 1])
    counts = scene_counts(scene, len(spheres))
    plane, sphere = scene_plane_pairs(spheres, planes, torch.tensor([0, 1, 1]), counts)
    expect = [(0, 0), (0, 1), (1, 2), (1, 3), (1, 4), (2, 2), (2, 3), (2, 4)]
    assert list(zip(plane.tolist(), sphere.tolist(), strict=True)) == expect


def test_compact_is_nonzero_given_its_count():
    mask = torch.rand(500, generator=torch.Generator().manual_seed(0)) < 0.3
    assert_close(compact(mask, int(mask.sum())), torch.nonzero(mask).flatten())
    assert compact(torch.zeros(4, dtype=torch.bool), 0).numel() == 0


@pytest.mark.parametrize("backend", ["torch", "kdtree"])
@pytest.mark.parametrize("connectivity", ["epsilon", "vi", "vmax"])
def test_all_pairs_candidates_give_the_radius_search_graph_bit_for_bit(
    monkeypatch, backend, connectivity
):
    for seed in range(4):
        state = random_batch(seed)
        builder = GraphBuilder(connectivity, epsilon=0.2, backend=backend)
        fast = builder(state)
        monkeypatch.setattr(builder_module, "ALL_PAIRS_MAX", 0)
        monkeypatch.setattr(builder_module, "ALL_PAIRS_PER_SPHERE", 0)
        monkeypatch.setattr(builder_module, "CPU_PAIRS_PER_SPHERE", 0)
        searched = builder(state)
        monkeypatch.undo()
        assert fast.num_pairs > 0 and fast.ps_index.shape[1] > 0
        for key in ("pp_index", "pp_attr", "ps_index", "ps_attr", "allowance"):
            assert torch.equal(getattr(fast, key), getattr(searched, key)), key


def test_a_graph_build_reads_back_once_with_the_layout_on_the_host():
    state, bare = random_batch(0), random_batch(0, host=False)
    with counting() as c:
        GraphBuilder()(state)
    assert c.syncs == 1
    with counting() as c:  # without it, the layout is counted and read back too
        GraphBuilder()(bare)
    assert c.syncs == 2


def test_a_single_scene_needs_no_layout():
    state = make_state([[0, 0, 0.5], [0.9, 0, 0.5], [5, 0, 3]])
    with counting() as c:
        GraphBuilder()(state)
    assert c.syncs == 1


def test_the_finite_watch_names_the_first_bad_step_in_time():
    watch = FiniteWatch()
    losses = [1.0, 2.0, float("nan"), 3.0, float("inf")]
    for step, value in enumerate(losses):  # fewer than FINITE_CHECK_EVERY: no read yet
        watch.update(torch.tensor(value), 0, step, last_batch=False)
    with pytest.raises(NonFiniteLossError, match=r"\(nan\) at epoch 0, step 2"):
        watch.update(torch.tensor(1.0), 0, 5, last_batch=True)
    watch = FiniteWatch()
    with pytest.raises(NonFiniteLossError, match="step 13"):
        for step in range(10, 10 + FINITE_CHECK_EVERY + 5):
            value = float("nan") if step == 13 else 1.0
            watch.update(torch.tensor(value), 1, step, last_batch=False)
    assert step == 10 + FINITE_CHECK_EVERY - 1


@pytest.fixture(scope="module")
def bench_cfg():
    bench = compose_config("bench")  # its lit: the training recipe with the bench's deltas
    cfg = bench.gpu_readiness
    return cfg, OmegaConf.merge(bench.model, cfg.model)


def test_a_training_step_stays_within_its_sync_budget(tiny_dataset, bench_cfg):
    cfg, model = bench_cfg
    trajectories = read_split(tiny_dataset / "train.h5")
    stats = json.loads((tiny_dataset / "stats.json").read_text())
    c = OmegaConf.create({"steps": 6, "warmup_steps": 1, "batch_size": 16})
    counts = training_step_counts(model, cfg.lit, trajectories, stats, c)
    assert 0 < counts["syncs"] <= TRAIN_STEP_SYNCS, counts["where"]


def test_a_rollout_frame_stays_within_its_sync_budget(tiny_dataset, bench_cfg):
    _, model = bench_cfg
    trajectory = read_split(tiny_dataset / "test.h5")[0]
    stats = json.loads((tiny_dataset / "stats.json").read_text())
    counts = rollout_frame_counts(model, stats, trajectory, 4)
    assert counts["syncs"] <= ROLLOUT_FRAME_SYNCS, counts["where"]


def test_a_rollout_is_the_same_with_either_candidate_path(tiny_dataset, bench_cfg, monkeypatch):
    _, model = bench_cfg
    stats = json.loads((tiny_dataset / "stats.json").read_text())
    torch.manual_seed(0)
    simulator = instantiate(model, stats=stats).eval()
    trajectories = read_split(tiny_dataset / "test.h5")[:3]
    fast = rollout(simulator, trajectories, n_frames=12)
    monkeypatch.setattr(builder_module, "ALL_PAIRS_MAX", 0)
    monkeypatch.setattr(builder_module, "ALL_PAIRS_PER_SPHERE", 0)
    monkeypatch.setattr(builder_module, "CPU_PAIRS_PER_SPHERE", 0)
    searched = rollout(simulator, trajectories, n_frames=12)
    for a, b in zip(fast, searched, strict=True):
        assert (a.pos == b.pos).all() and (a.vel == b.vel).all()


def test_a_pair_dataset_on_another_device_gathers_there(tiny_dataset):
    pairs = PairDataset(read_split(tiny_dataset / "train.h5"), H=2, future=2)
    index = torch.tensor([3, 0, 7])
    here = pairs.batch(index)
    moved = pairs.to("meta").batch(index)  # no computation: any tensor left behind would fail
    assert moved.host_sizes == here.host_sizes
    for key in ("pos", "vel", "planes", "future_pos", "batch", "plane_batch", "ptr"):
        assert moved[key].device.type == "meta" and moved[key].shape == here[key].shape, key
