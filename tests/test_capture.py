"""The capture path: graphs padded to capacity buckets give the unpadded outputs, in a few
fixed shapes; a compiled network keeps to a bound of shapes and says when it runs past it."""

from __future__ import annotations

import warnings

import pytest
import torch
from handmade import scene
from simdata import learned
from torch.testing import assert_close

from physgnn.models.capture import (
    ShapeBoundCall,
    compile_in_place,
    compile_simulator,
    recompile_limit,
)
from physgnn.nn.epd import EncodeProcessDecode, Widths
from physgnn.nn.padding import bucket, pad_graph
from physgnn.training.runs import load_run


def test_buckets_cover_every_size_with_at_most_a_fifth_of_padding():
    sizes = [bucket(n) for n in range(0, 5000)]
    assert all(b >= n for n, b in enumerate(sizes))
    assert all(b <= max(8, 1.19 * n + 1) for n, b in enumerate(sizes))
    assert len(set(sizes[1000:2000])) <= 5  # a doubling of sizes: 4 or 5 shapes


def random_graph(n: int, pairs: int, f: int, seed: int = 0):
    gen = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 5, generator=gen)
    i = torch.randint(0, n, (pairs,), generator=gen)
    j = (i + 1 + torch.randint(0, n - 1, (pairs,), generator=gen)) % n
    attr = torch.randn(pairs, 4, generator=gen)
    pp_index = torch.cat([torch.stack([i, j]), torch.stack([j, i])], 1)
    pp_attr = torch.cat([attr, attr * torch.tensor([-1.0, -1, -1, 1])])
    ps_index = torch.stack(
        [torch.zeros(f, dtype=torch.long), torch.randint(0, n, (f,), generator=gen)]
    )
    return x, pp_index, pp_attr, ps_index, torch.randn(f, 10, generator=gen)


@pytest.mark.parametrize("n, pairs, f", [(5, 4, 5), (37, 60, 40), (100, 0, 100)])
def test_a_padded_graph_gives_the_network_the_same_outputs(n, pairs, f):
    torch.manual_seed(1)
    net = EncodeProcessDecode(Widths(5, 4, 10), hidden=16, M=2).eval()
    graph = random_graph(n, pairs, f)
    padded, real = pad_graph(*graph)
    assert real == n and padded[0].shape[0] == bucket(n + 1)
    assert padded[1].shape[1] == 2 * bucket(pairs) and padded[3].shape[1] == bucket(f)
    half = padded[1].shape[1] // 2  # the paired layout holds
    assert torch.equal(padded[1][:, half:], padded[1][:, :half].flip(0))
    with torch.no_grad():
        assert_close(net(*padded)[:n], net(*graph), rtol=1e-5, atol=1e-5)


def test_the_padded_simulator_predicts_as_the_plain_one():
    torch.manual_seed(0)
    plain = learned(H=1, M=2, hidden=16, gravity_prior=True).eval()
    padded = learned(H=1, M=2, hidden=16, gravity_prior=True, pad_to_buckets=True)
    padded.load_state_dict(plain.state_dict())
    state = scene(
        [[0, 0, 0.5], [0.9, 0, 0.5], [3, 0, 2.0]],
        [[1, 0, 0], [-1, 0, 0], [0, 0, -2]],
        [0.5, 0.5, 0.5],
    )
    with torch.no_grad():
        for a, b in zip(plain(state), padded.eval()(state), strict=True):
            assert_close(a, b, rtol=1e-5, atol=1e-6)


@pytest.mark.slow
def test_the_compiled_padded_network_equals_eager_and_keeps_its_shapes():
    torch.manual_seed(1)
    net = EncodeProcessDecode(Widths(5, 4, 10), hidden=16, M=2).eval()
    compiled = torch.compile(net, dynamic=False)
    with torch.no_grad():
        for n, pairs in ((30, 40), (31, 42)):  # the same buckets: one compiled graph
            graph = random_graph(n, pairs, n)
            padded, _ = pad_graph(*graph)
            assert_close(compiled(*padded)[:n], net(*graph), rtol=1e-4, atol=1e-5)


def test_a_compiled_network_keeps_its_weights_and_warns_past_its_shapes():
    torch.manual_seed(2)
    net = EncodeProcessDecode(Widths(5, 4, 10), hidden=8, M=1).eval()
    keys = set(net.state_dict())
    compile_in_place(net, max_shapes=2, backend="eager")  # no code generation: the logic only
    assert set(net.state_dict()) == keys and isinstance(net.forward, ShapeBoundCall)
    graphs = [random_graph(n, n, n) for n in (6, 7, 8)]
    with torch.no_grad():
        first = [net(*g) for g in graphs[:2]]
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            net(*graphs[0])  # a shape it has compiled: no warning
        with pytest.warns(UserWarning, match="more than 2 input shapes.*pad_to_buckets"):
            third = net(*graphs[2])
        eager = ShapeBoundCall(net, backend="eager").eager
        for graph, out in zip(graphs, [*first, third], strict=True):
            assert_close(out, eager(*graph))
    assert len(net.forward.keys) == 2


def test_dynamic_shapes_count_as_one_shape_whatever_the_graph_sizes():
    net = EncodeProcessDecode(Widths(5, 4, 10), hidden=8, M=1).eval()
    compile_in_place(net, dynamic=True, max_shapes=2, backend="eager")
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("error")  # 20 sizes, one graph: never past the bound
        for n in range(6, 26):
            net(*random_graph(n, n, n))
    assert len(net.forward.keys) == 1


def test_compile_options_are_checked_in_one_line():
    net = EncodeProcessDecode(Widths(5, 4, 10), hidden=8, M=1)
    with pytest.raises(ValueError, match="unknown compile mode 'fast'"):
        ShapeBoundCall(net, mode="fast")
    with pytest.raises(ValueError, match="max_shapes must be >= 1"):
        ShapeBoundCall(net, max_shapes=0)


def test_dynamos_limit_grows_with_every_compiled_module():
    """Dynamo counts the compiles of one code object over every module of the process: with
    the limit at one module's bound, the regions of the third simulator compiled would run
    eager past it."""
    before = ShapeBoundCall.bounds
    for _ in range(3):
        compile_in_place(torch.nn.Linear(2, 2), "default", True, 5, backend="eager")
    assert ShapeBoundCall.bounds == before + 15
    assert recompile_limit() >= ShapeBoundCall.bounds


@pytest.mark.slow
def test_the_shipped_step_traces_without_a_word_from_dynamo():
    # dynamo warns where it may trace something other than what runs eager (a cache wrapper
    # it ignores, a graph break); the shipped step, compiled as simulate and eval compile it
    sim = load_run("pretrained")[0].eval()
    compile_simulator(sim, backend="eager")  # tracing alone, no code generation
    state = scene(
        [[0, 0, 0.5], [0.9, 0, 0.5], [3, 0, 2.0]],
        [[1, 0, 0], [-1, 0, 0], [0, 0, -2]],
        [0.5, 0.5, 0.5],
    )
    eager = load_run("pretrained")[0].eval()
    with warnings.catch_warnings(record=True) as caught, torch.no_grad():
        warnings.simplefilter("always")
        compiled = sim(state)
    assert [str(w.message) for w in caught] == []
    with torch.no_grad():
        for a, b in zip(compiled, eager(state), strict=True):
            assert_close(a, b)
