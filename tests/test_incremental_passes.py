"""A pass after a rebuild recomputes only what the change can reach (physgnn/nn/reuse.py,
physgnn/nn/changes.py, model.contacts.incremental_passes): the whole pass's numbers up to float
rounding, on random graphs of the network alone and on random supported scenes of the
simulator, with random and with the shipped weights."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from handmade import DT, make, scene
from torch.testing import assert_close

from physgnn.models import passes
from physgnn.nn import EncodeProcessDecode, Widths, reuse
from physgnn.nn.changes import changes, hops
from physgnn.training.runs import load_run

NETWORKS = [
    {},  # the default model's network (mean aggregation, third law, surfaces)
    {"aggregation": "sum", "layer_norm": True},
    {"third_law": False, "use_surfaces": False},
    {"num_materials": 3, "material_dim": 2},
]


def paired(pairs: torch.Tensor) -> torch.Tensor:
    """``[2, E]`` in the paired layout from pairs ``[2, E/2]`` (j < i)."""
    return torch.cat([pairs, pairs.flip(0)], 1)


def inputs(pairs: torch.Tensor, ps_index: torch.Tensor, x: torch.Tensor, material) -> tuple:
    """The network inputs of a graph: edge features are functions of the edge's ends, so an
    edge in two graphs has the same features in both."""
    pp_index = paired(pairs)
    src, dst = pp_index.double()
    pp_attr = torch.stack([torch.sin(src + 0.3 * dst), torch.cos(0.7 * src - dst), src - dst], 1)
    plane, sphere = ps_index.double()
    ps_attr = torch.stack([torch.sin(sphere), plane, torch.cos(2 * sphere)], 1)
    return x, pp_index, pp_attr.float(), ps_index, ps_attr.float(), material


def two_graphs(seed: int, n: int = 80) -> tuple:
    """The inputs of a sparse random graph and of a second one with some pairs and ps edges
    added, a few removed, one ps row and one node row changed (what a pass and a rebuild may
    differ in)."""
    gen = torch.Generator().manual_seed(seed)
    every = torch.combinations(torch.arange(n), 2).T
    first = torch.rand(every.shape[1], generator=gen) < 0.03
    second = first & (torch.rand(every.shape[1], generator=gen) > 0.05)
    second |= torch.rand(every.shape[1], generator=gen) < 0.002
    x = torch.randn(n, 5, generator=gen)
    material = torch.randint(0, 3, (n,), generator=gen)
    ground = torch.stack([torch.zeros(n // 2, dtype=torch.long), torch.arange(n // 2)])
    wall = torch.tensor([[1, 1], [n - 2, n - 1]])
    moved = x.clone()
    moved[7] += 1.0  # a node whose input row differs
    earlier = inputs(every[:, first], ground, x, material)
    later = inputs(every[:, second], torch.cat([ground, wall], 1), moved, material)
    later[4][3, 0] += 1.0  # a ps row whose features differ (a clip moved, say)
    return earlier, later


@pytest.mark.parametrize("options", NETWORKS)
def test_a_pass_again_equals_the_whole_pass_on_random_graphs(options):
    torch.manual_seed(0)
    widths = Widths(node_in=5, pp_in=3, ps_in=3, out_dim=7, pair_out=6)
    net = EncodeProcessDecode(widths, hidden=16, M=3, **options)
    for seed in range(4):
        earlier, later = two_graphs(seed)
        if net.material is None:
            earlier, later = earlier[:5] + (None,), later[:5] + (None,)
        out, pairs, kept = reuse.whole(net, *earlier, pairs=True)
        assert_close((out, pairs), net.forward_pairs(*earlier), rtol=0, atol=0)
        again_out, again_pairs, kept_again = reuse.again(net, kept, *later, pairs=True)
        assert_close((again_out, again_pairs), net.forward_pairs(*later))
        back = reuse.again(net, kept_again, *earlier, pairs=True)[:2]  # edges removed
        assert_close(back, (out, pairs))


def test_gradients_through_a_pass_again_are_the_whole_pass_s():
    """A kept latent is the same function of the weights as the one the whole pass computes
    (the inputs within its reach are the same), so the gradients agree too."""
    torch.manual_seed(0)
    widths = Widths(node_in=5, pp_in=3, ps_in=3, out_dim=7, pair_out=6)
    net = EncodeProcessDecode(widths, hidden=16, M=3)
    earlier, later = (inputs[:5] + (None,) for inputs in two_graphs(1))
    params = list(net.parameters())

    def gradients(out, pairs):
        return torch.autograd.grad(out.square().sum() + pairs.square().sum(), params)

    kept = reuse.whole(net, *earlier, pairs=True)[2]
    again = gradients(*reuse.again(net, kept, *later, pairs=True)[:2])
    assert_close(again, gradients(*net.forward_pairs(*later)))


def test_the_decoder_sees_only_the_spheres_within_m_hops_of_the_change():
    torch.manual_seed(0)
    net = EncodeProcessDecode(Widths(node_in=5, pp_in=3, ps_in=3), hidden=16, M=2)
    n = 40
    chain = torch.stack([torch.arange(n - 1), torch.arange(1, n)])  # 0 - 1 - ... - 39
    x = torch.randn(n, 5)
    ground = torch.stack([torch.zeros(n, dtype=torch.long), torch.arange(n)])
    earlier = inputs(chain[:, 1:], ground, x, None)  # the pair (0, 1) is new in the second
    later = inputs(chain, ground, x, None)
    rows = []
    net.decoder.register_forward_hook(lambda module, args, out: rows.append(args[0].shape[0]))
    kept = reuse.whole(net, *earlier)[2]
    out = reuse.again(net, kept, *later)[0]
    assert_close(out, net(*later))
    # whole, again (spheres 0..2: one hop from the new pair's ends after 2 blocks), whole
    assert rows == [n, 3, n]
    found = changes(kept, *later)
    assert found.seed.nonzero().flatten().tolist() == [0, 1]
    assert [int(d.sum()) for d in hops(found.seed, later[1], 3)] == [2, 3, 4, 5]
    moved = x.clone()
    moved[20] += 1.0  # an input row: its latent differs from the encoder on, so one hop more
    assert changes(kept, *inputs(chain[:, 1:], ground, moved, None)).seed.sum() == 3


def test_nothing_changed_recomputes_nothing():
    torch.manual_seed(0)
    net = EncodeProcessDecode(Widths(node_in=5, pp_in=3, ps_in=3), hidden=16, M=2)
    earlier, _ = two_graphs(0)
    earlier = earlier[:5] + (None,)
    out, _, kept = reuse.whole(net, *earlier)
    again_out, _, kept_again = reuse.again(net, kept, *earlier)
    assert torch.equal(again_out, out)
    assert all(torch.equal(a, b) for a, b in zip(kept_again.nodes, kept.nodes, strict=True))


def supported_pile(seed: int):
    """A row of spheres resting on the ground, some resting on top of them, and spheres falling
    or thrown onto them within a frame or two (so a rebuild on the provisional velocities adds
    edges: a resting sphere stops, the one falling on it does not)."""
    rng = np.random.default_rng(seed)
    row = 10
    radius = np.concatenate([rng.uniform(0.45, 0.5, row), np.full(8, 0.5)])
    x = np.cumsum(2 * radius[:row] + 0.004) - radius[:row]
    pos = [np.stack([x, np.zeros(row), radius[:row]], 1)]
    vel = [np.zeros((row, 3))]
    columns = rng.permutation(row)
    on_top, above, aside = columns[:3], columns[3:7], columns[7]
    pos.append(np.stack([x[on_top], np.zeros(3), 2 * radius[on_top] + 0.5 + 0.002], 1))
    vel.append(np.zeros((3, 3)))
    # falling at v onto a resting sphere, the gap between v·dt (the ballistic pair's approach:
    # gravity cancels) and (v + g·dt)·dt (the approach once the resting one is stopped)
    speed = rng.uniform(1, 3, 4)
    height = 2 * radius[above] + 0.5 + DT * speed + rng.uniform(0.02, 0.08, 4)
    pos.append(np.stack([x[above] + rng.uniform(-0.05, 0.05, 4), np.zeros(4), height], 1))
    vel.append(np.stack([np.zeros(4), np.zeros(4), -speed], 1))
    # one thrown at the row from the side
    pos.append([[x[aside], 1.2, radius[aside] + 0.3]])
    vel.append([[0.0, -3.0, 0.0]])
    pos, vel = np.concatenate(pos), np.concatenate(vel)
    return scene(pos, vel, radius, material=rng.integers(0, 2, len(pos)))


def passes_of(sim, state, incremental: bool, monkeypatch) -> tuple:
    """``(motion, graph, reused)``: ``sim``'s step on ``state`` with or without incremental
    passes, and how many passes reused an earlier one's latents."""
    sim.contacts = dataclasses.replace(sim.contacts, incremental_passes=incremental)
    reused = []

    def counting(net, earlier, *args, **kwargs):
        reused.append(earlier is not None)
        return reuse.again(net, earlier, *args, **kwargs)

    monkeypatch.setattr(passes, "again", counting)
    with torch.no_grad():
        motion, graph = sim.predict_motion(state)
    return motion, graph, sum(reused)


@pytest.mark.parametrize("weights", ["random", "shipped"])
def test_incremental_passes_give_the_whole_passes_answer_on_supported_piles(weights, monkeypatch):
    sim = (make(M=5, hidden=32) if weights == "random" else load_run("pretrained")[0]).eval()
    assert sim.contacts.incremental_passes  # the default
    reused = 0
    for seed in range(6):
        state = supported_pile(seed)
        whole, whole_graph, none = passes_of(sim, state, False, monkeypatch)
        again, graph, count = passes_of(sim, state, True, monkeypatch)
        assert none == 0
        reused += count
        assert torch.equal(graph.pp_index, whole_graph.pp_index)
        assert_close(again, whole)
    assert reused > 0  # some rebuilds added edges, and their passes reused
