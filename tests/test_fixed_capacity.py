"""Fixed-capacity graphs: every candidate of the layout, padded to a bucket, with masks; the
same edges, predictions and losses as the counted graph, and nothing read back."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from gpukit import training_batch
from handmade import make_state, random_batch
from hydra.utils import instantiate
from omegaconf import OmegaConf
from torch.testing import assert_close

from physgnn import CONF_DIR
from physgnn.benchmark.gpu_readiness import training_step_counts
from physgnn.benchmark.syncs import counting
from physgnn.cli import compose_config
from physgnn.graph.builder import GraphBuilder
from physgnn.graph.rules import CONNECTIVITIES
from physgnn.nn.padding import bucket
from physgnn.training.contacts import perturb_contacts

EDGE_KEYS = ("pp_index", "pp_attr", "ps_index", "ps_attr", "allowance")


@pytest.mark.parametrize("connectivity", CONNECTIVITIES)
def test_the_accepted_edges_are_the_counted_graph_bit_for_bit(connectivity):
    for seed in range(4):
        state = random_batch(seed)
        counted = GraphBuilder(connectivity, epsilon=0.2)(state)
        fixed = GraphBuilder(connectivity, epsilon=0.2, fixed_capacity=True)(state)
        assert fixed.masked and not counted.masked and counted.num_pairs > 0
        for key in EDGE_KEYS:
            assert torch.equal(getattr(fixed.compacted(), key), getattr(counted, key)), key


def test_capacities_are_the_layouts_candidates_and_the_network_sees_buckets(tiny_train):
    _, simulator = simulators(tiny_train[1])
    state = training_batch(tiny_train[0], simulator.H)
    spheres, planes = state.host_sizes
    pairs = sum(n * (n - 1) // 2 for n in spheres)
    plane_pairs = sum(n * s for n, s in zip(spheres, planes, strict=True))
    g = simulator.graph_builder(state)
    assert g.num_pairs == pairs and g.ps_index.shape[1] == plane_pairs
    assert torch.equal(g.pp_mask[:pairs], g.pp_mask[pairs:])  # the paired layout
    shapes = []
    network, process = simulator.network, simulator.network.process

    def watched(*args):
        shapes.append([a.shape for a in args[:5]])
        return process(*args)

    network.process = watched
    with torch.no_grad():
        simulator.predict(state)
    x, pp_index, _, ps_index, _ = shapes[0]
    n = state.pos.shape[0]
    assert (x[0], pp_index[1], ps_index[1]) == (
        bucket(n + 1),
        2 * bucket(pairs),
        bucket(plane_pairs),
    )


def test_a_fixed_capacity_build_reads_nothing_back():
    state = random_batch(0)
    with counting() as c:
        GraphBuilder(fixed_capacity=True)(state)
    assert c.syncs == 0 and c.kernels > 0
    with counting() as c:
        GraphBuilder()(state)
    assert c.syncs == 1


def test_network_inputs_send_masked_edges_to_the_ghost_node():
    state = random_batch(2)
    g = GraphBuilder(fixed_capacity=True)(state)
    n = state.pos.shape[0]
    pp_index, pp_attr, ps_index, ps_attr = g.network_inputs(n, g.pp_attr, g.ps_attr)
    assert torch.equal(pp_index[:, g.pp_mask], g.pp_index[:, g.pp_mask])
    assert (pp_index[:, ~g.pp_mask] == n).all() and (pp_attr[~g.pp_mask] == 0).all()
    assert (ps_index[1, ~g.ps_mask] == n).all() and (ps_attr[~g.ps_mask] == 0).all()
    assert torch.equal(ps_index[0], g.ps_index[0])


def simulators(stats, **overrides):
    """The default model twice with the same random weights: counted and fixed capacity."""
    model = OmegaConf.load(Path(CONF_DIR) / "model/baseline.yaml")
    out = []
    for fixed in (False, True):
        torch.manual_seed(0)
        cfg = OmegaConf.merge(model, {"graph": {"fixed_capacity": fixed}}, overrides)
        out.append(instantiate(cfg, stats=stats))
    return out


FD_STATE = {"inputs": {"engine_state": False}, "contacts": {"plane_floor": False}}


@pytest.mark.parametrize("overrides", [{}, FD_STATE], ids=["default", "fd_state"])
def test_predictions_and_losses_equal_the_counted_graphs(tiny_train, overrides):
    trajectories, stats = tiny_train
    counted, fixed = simulators(stats, **overrides)
    recipe = compose_config("bench").gpu_readiness.lit  # the training recipe, the bench's deltas
    lit = [instantiate(recipe, simulator=s) for s in (counted, fixed)]
    batch = training_batch(trajectories, counted.H)
    with torch.no_grad():
        (m0, g0), (m1, g1) = counted.predict_motion(batch), fixed.predict_motion(batch)
        assert g1.masked and g1.num_pairs > g0.num_pairs
        for a, b in zip(m1, m0, strict=True):
            assert_close(a, b)
        losses0, losses1 = lit[0].losses(batch), lit[1].losses(batch)
    if overrides:  # the floor keeps the default's moves out of the planes
        assert losses0["loss_contact"] > 0  # the penalty is exercised
    for key, value in losses0.items():
        assert_close(losses1[key], value, msg=key)


def test_contact_noise_pushes_only_the_accepted_contacts():
    # separating, 0.02 m apart: within the noise's touch, outside the approach rule's 0.01 shell
    state = make_state([[0, 0, 5], [1.02, 0, 5]], vel=[[-1, 0, 0], [1, 0, 0]])
    g = GraphBuilder(fixed_capacity=True)(state)
    assert g.num_pairs > 0 and not g.pp_mask.any()
    out = perturb_contacts(state, g, depth=0.3, touch=0.05, prob=1.0)
    assert torch.equal(out.pos, state.pos)


def test_a_training_step_on_fixed_capacity_graphs_reads_back_at_most_the_finiteness(tiny_train):
    trajectories, stats = tiny_train
    cfg = compose_config("bench").gpu_readiness
    model = OmegaConf.merge(OmegaConf.load(Path(CONF_DIR) / "model/baseline.yaml"), cfg.model)
    model.graph.fixed_capacity = True
    c = OmegaConf.create({"steps": 6, "warmup_steps": 1, "batch_size": 16})
    counts = training_step_counts(model, cfg.lit, trajectories, stats, c)
    assert counts["syncs"] <= 1, counts["where"]
