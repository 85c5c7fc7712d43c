"""The graph network on hand-built graphs of a few nodes (physgnn.nn)."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from torch.testing import assert_close
from torch.utils.flop_counter import FlopCounterMode

from physgnn.nn import MLP, EncodeProcessDecode, InteractionBlock, SurfaceBlock, Widths

H = 8  # latent width of the small test models
NODE_IN = 5
PAIRS = [(0, 1), (1, 2), (2, 3), (0, 2)]  # (source j, target i) of the first half
CONCAT_MODES = ("never", "always", "auto")  # the first one is the reference path


def paired(pairs: list[tuple[int, int]]) -> torch.Tensor:
    """Paired layout ``[2, E]``: edge ``e + E/2`` is the reverse of edge ``e``."""
    src, dst = torch.tensor(pairs, dtype=torch.long).T
    return torch.stack([torch.cat([src, dst]), torch.cat([dst, src])])


def graph(seed: int = 0, n: int = 5, pairs=PAIRS) -> dict:
    """5 spheres, 4 pp pairs (E = 8); planes 0 (ground, all spheres) and 1 (spheres 3, 4)."""
    g = torch.Generator().manual_seed(seed)
    ps_index = torch.tensor([[0, 0, 0, 0, 0, 1, 1], [0, 1, 2, 3, 4, 3, 4]])
    pp_index = paired(pairs) if pairs else torch.zeros(2, 0, dtype=torch.long)
    return dict(
        x=torch.randn(n, NODE_IN, generator=g),
        pp_index=pp_index,
        pp_attr=torch.randn(pp_index.shape[1], 4, generator=g),
        ps_index=ps_index,
        ps_attr=torch.randn(ps_index.shape[1], 10, generator=g),
    )


WIDTHS = {field.name for field in dataclasses.fields(Widths)}


def model(seed: int = 0, **kwargs) -> EncodeProcessDecode:
    """A network of ``hidden`` H, M = 3 and ``kwargs`` (the :class:`Widths` among them)."""
    torch.manual_seed(seed)
    widths = {"node_in": NODE_IN} | {k: kwargs.pop(k) for k in WIDTHS & set(kwargs)}
    return EncodeProcessDecode(Widths(**widths), **{"hidden": H, "M": 3, **kwargs})


def test_mlp_is_linear_relu_linear_and_resets():
    torch.manual_seed(0)
    mlp = MLP(3, 4, 2)
    x = torch.randn(5, 3)
    expected = torch.relu(x @ mlp.lin1.weight.T + mlp.lin1.bias) @ mlp.lin2.weight.T
    assert_close(mlp(x), expected + mlp.lin2.bias)
    w1, w2 = mlp.first_layer_blocks([1, 2])
    pre = x[:, :1] @ w1.T + x[:, 1:] @ w2.T + mlp.lin1.bias
    assert_close(mlp.finish(pre), mlp(x))
    before = mlp.lin1.weight.clone()
    mlp.reset_parameters()
    assert not torch.equal(before, mlp.lin1.weight)
    assert mlp.flops(5) == 2 * 5 * (3 * 4 + 4 * 2)


def op_inputs(seed: int = 1):
    g = torch.Generator().manual_seed(seed)
    edge_index = paired(PAIRS)
    return torch.randn(5, H, generator=g), edge_index, torch.randn(8, H, generator=g)


@pytest.mark.parametrize("concat_trick", ["never", "always"])
def test_third_law_messages_exactly_opposite_and_match_brute_force(concat_trick):
    torch.manual_seed(0)
    op = InteractionBlock(H, third_law=True, concat_trick=concat_trick)
    x, edge_index, e = op_inputs()
    agg, m = op(x, edge_index, e)
    assert m.shape == (8, H) and agg.shape == (5, H)
    assert torch.equal(m[4:], -m[:4])
    src, dst = edge_index[:, :4]
    forward = op.mlp(torch.cat([x[dst], x[src], e[:4]], dim=1))
    backward = op.mlp(torch.cat([x[src], x[dst], e[4:]], dim=1))
    assert_close(m[:4], 0.5 * (forward - backward))
    expected = torch.zeros(5, H).index_add_(0, edge_index[1], m)
    assert_close(agg, expected)
    assert_close(agg.sum(0), torch.zeros(H), atol=1e-6, rtol=0)


def test_without_third_law_every_edge_is_computed_on_its_own():
    torch.manual_seed(0)
    op = InteractionBlock(H, third_law=False, concat_trick="never")
    x, edge_index, e = op_inputs()
    agg, m = op(x, edge_index, e)
    src, dst = edge_index
    assert_close(m, op.mlp(torch.cat([x[dst], x[src], e], dim=1)))
    assert_close(agg, torch.zeros(5, H).index_add_(0, dst, m))
    assert not torch.allclose(m[4:], -m[:4])


@pytest.mark.parametrize("third_law", [True, False])
def test_concat_trick_equals_plain_path(third_law):
    x, edge_index, e = op_inputs()
    ops = {}
    for mode in ("never", "always"):
        torch.manual_seed(0)
        ops[mode] = InteractionBlock(H, third_law=third_law, concat_trick=mode)
    agg_plain, m_plain = ops["never"](x, edge_index, e)
    agg_fast, m_fast = ops["always"](x, edge_index, e)
    assert_close(m_fast, m_plain)
    assert_close(agg_fast, agg_plain)
    g = graph()
    outs = [model(third_law=third_law, concat_trick=mode)(**g) for mode in CONCAT_MODES]
    assert_close(outs[1], outs[0])
    assert_close(outs[2], outs[0])


def test_auto_picks_concat_trick_only_when_cheaper():
    op = InteractionBlock(H, third_law=True, concat_trick="auto")
    assert op.uses_concat(num_nodes=154, num_msg=300)
    assert not op.uses_concat(num_nodes=1000, num_msg=3)
    # sparse contacts: plain first layer on the 6 edges, second layer once per pair (3)
    assert op.flops(1000, 6) == 2 * (6 * 3 * H * H + 3 * H * H)
    with pytest.raises(ValueError, match="concat_trick"):
        InteractionBlock(H, concat_trick="yes")


def test_surface_messages_match_brute_force():
    torch.manual_seed(0)
    op = SurfaceBlock(H)
    g = torch.Generator().manual_seed(2)
    x = torch.randn(5, H, generator=g)
    edge_index = torch.tensor([[0, 0, 0, 0, 0, 1, 1], [0, 1, 2, 3, 4, 3, 4]])
    e = torch.randn(7, H, generator=g)
    m = op.mlp(torch.cat([x[edge_index[1]], e], dim=1))
    assert_close(op(x, edge_index, e), torch.zeros(5, H).index_add_(0, edge_index[1], m))


def brute_force_pp(op: InteractionBlock, x, edge_index, e):
    """The pp sums straight from the definition: the MLP on ``[v_i, v_j, e_ij]`` per edge,
    antisymmetrised over each pair with ``third_law``."""
    src, dst = edge_index
    m = op.mlp(torch.cat([x[dst], x[src], e], dim=1))
    if op.third_law:
        half = m.shape[0] // 2
        m = torch.cat([0.5 * (m[:half] - m[half:]), 0.5 * (m[half:] - m[:half])])
    return torch.zeros(x.shape[0], H).index_add_(0, dst, m)


def brute_force_ps(op: SurfaceBlock, x, edge_index, e):
    """The ps sums straight from the definition: the MLP on ``[v_i, e_is]`` per edge."""
    m = op.mlp(torch.cat([x[edge_index[1]], e], dim=1))
    return torch.zeros(x.shape[0], H).index_add_(0, edge_index[1], m)


@pytest.mark.parametrize("kind", ["pp_third_law", "pp_plain", "pp_concat", "ps"])
def test_operator_gradients_match_brute_force(kind):
    """The operators' rearranged products (second layer once per pair or per sphere, first
    layer split by blocks) give the gradients of the definition, for inputs and weights."""
    torch.manual_seed(0)
    if kind == "ps":
        op, reference = SurfaceBlock(H), brute_force_ps
        x, _, _ = op_inputs()
        edge_index = torch.tensor([[0, 0, 0, 0, 0, 1, 1], [0, 1, 2, 3, 4, 3, 4]])
        e = torch.randn(7, H)
    else:
        trick = "always" if kind == "pp_concat" else "never"
        op = InteractionBlock(H, third_law=kind != "pp_plain", concat_trick=trick)
        reference = brute_force_pp
        x, edge_index, e = op_inputs()
    weights = torch.randn(5, H)
    grads = []
    for fn in (lambda *a: op(*a)[0] if kind != "ps" else op(*a), lambda *a: reference(op, *a)):
        xs, es = x.clone().requires_grad_(), e.clone().requires_grad_()
        op.zero_grad()
        (fn(xs, edge_index, es) * weights).sum().backward()
        grads.append([xs.grad, es.grad] + [p.grad.clone() for p in op.parameters()])
    for fast, slow in zip(*grads, strict=True):
        assert_close(fast, slow)


def capture_pp_calls(net: EncodeProcessDecode) -> list:
    """Record ``(e_pp input, messages output)`` of every block's pp operator."""
    calls = []
    for block in net.blocks:
        block.pp.register_forward_hook(lambda mod, args, out: calls.append((args[2], out[1])))
    return calls


def test_pp_edge_latents_are_passed_on_from_block_to_block():
    net = model(M=3)
    g = graph()
    calls = capture_pp_calls(net)
    net(**g)
    assert len(calls) == 3
    assert_close(calls[0][0], net.pp_encoder(g["pp_attr"]))
    for (e_in, m), (e_next, _) in zip(calls[:-1], calls[1:], strict=True):
        assert torch.equal(e_next, e_in + m)  # the updated latents, not the encoder's
        assert not torch.allclose(e_next, e_in)
    assert not torch.allclose(calls[2][0], calls[0][0])


@pytest.mark.parametrize("third_law", [True, False])
def test_permutation_equivariance(third_law):
    net = model(third_law=third_law, num_materials=3, material_dim=2)
    g = graph()
    material = torch.tensor([0, 2, 1, 1, 0])
    out = net(**g, material=material)
    perm = torch.tensor([3, 0, 4, 1, 2])  # new node k is old node perm[k]
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(5)
    ps_index = torch.stack([g["ps_index"][0], inv[g["ps_index"][1]]])
    g_perm = dict(g, x=g["x"][perm], pp_index=inv[g["pp_index"]], ps_index=ps_index)
    assert_close(net(**g_perm, material=material[perm]), out[perm])
    # Reordering the pairs (both halves alike) and the ps edges changes nothing either.
    q = torch.tensor([2, 0, 3, 1])
    order = torch.cat([q, q + 4])
    f = torch.tensor([6, 0, 5, 1, 4, 2, 3])
    g_reordered = dict(
        g,
        pp_index=g["pp_index"][:, order],
        pp_attr=g["pp_attr"][order],
        ps_index=g["ps_index"][:, f],
        ps_attr=g["ps_attr"][f],
    )
    assert_close(net(**g_reordered, material=material), out)


@pytest.mark.parametrize("concat_trick", ["never", "always"])
def test_third_law_output_does_not_depend_on_pair_orientation(concat_trick):
    """Listing each pair (j, i) instead of (i, j) swaps the halves of the paired layout."""
    net = model(third_law=True, concat_trick=concat_trick)
    g = graph()
    e = g["pp_index"].shape[1] // 2
    swap = torch.cat([torch.arange(e, 2 * e), torch.arange(e)])
    g_swapped = dict(g, pp_index=g["pp_index"][:, swap], pp_attr=g["pp_attr"][swap])
    assert_close(net(**g_swapped), net(**g))


def test_identical_inputs_give_identical_outputs_in_one_batch():
    """Two copies of a scene (e.g. one translated: the network sees only relative features,
    so its inputs are identical) batched as one disconnected graph."""
    net = model()
    g = graph()
    out = net(**g)
    assert torch.equal(net(**g), out)
    ps_index = torch.cat([g["ps_index"], g["ps_index"] + torch.tensor([[2], [5]])], dim=1)
    half = g["pp_index"][:, :4]
    pp_index = torch.cat([half, half + 5, half.flip(0), half.flip(0) + 5], dim=1)
    pp_attr = torch.cat([g["pp_attr"][:4], g["pp_attr"][:4], g["pp_attr"][4:], g["pp_attr"][4:]])
    both = net(
        torch.cat([g["x"], g["x"]]),
        pp_index,
        pp_attr,
        ps_index,
        torch.cat([g["ps_attr"], g["ps_attr"]]),
    )
    assert_close(both[:5], out)
    assert_close(both[5:], out)


def test_every_parameter_receives_a_gradient():
    net = model(M=2, num_materials=3, material_dim=2)
    out = net(**graph(), material=torch.tensor([0, 1, 2, 1, 0]))
    out.square().sum().backward()
    for name, p in net.named_parameters():
        assert p.grad is not None, name
        assert p.grad.abs().sum() > 0, name


def count_linear_calls(modules) -> list:
    calls = []
    for module in modules:
        for sub in module.modules():
            if isinstance(sub, torch.nn.Linear):
                sub.register_forward_hook(lambda *_: calls.append(1))
    return calls


def test_no_pp_mlp_runs_without_pp_edges():
    net = model()
    pp_calls = count_linear_calls([net.pp_encoder] + [b.pp for b in net.blocks])
    out = net(**graph(pairs=[]))
    assert out.shape == (5, 6) and torch.isfinite(out).all()
    assert len(pp_calls) == 0
    net(**graph())  # control: the hooks do fire when there are pp edges
    assert len(pp_calls) > 0


@pytest.mark.parametrize("use_surfaces", [True, False])
def test_no_ps_mlp_runs_without_ps_edges(use_surfaces):
    net = model(use_surfaces=use_surfaces)
    ps_modules = [m for m in [net.ps_encoder] + [b.ps for b in net.blocks] if m is not None]
    ps_calls = []
    for module in ps_modules:
        module.register_forward_hook(lambda *_: ps_calls.append(1))
    g = graph()
    no_ps = dict(g, ps_index=g["ps_index"][:, :0], ps_attr=g["ps_attr"][:0])
    assert net(**no_ps).shape == (5, 6)
    assert len(ps_calls) == 0
    out = net(**g)
    assert len(ps_calls) == (4 if use_surfaces else 0)  # encoder + 3 blocks
    if not use_surfaces:
        assert ps_modules == []
        assert torch.equal(out, net(**no_ps))  # ps inputs are ignored


def test_gns_style_baseline_accepts_any_edge_order():
    net = model(third_law=False, use_surfaces=False)
    g = graph()
    one_way = dict(g, pp_index=g["pp_index"][:, :5], pp_attr=g["pp_attr"][:5])
    assert net(**one_way).shape == (5, 6)
    assert not any("ps" in name for name, _ in net.named_parameters())


def test_flops_per_step_hand_computed():
    # h = 8, node_in 5, pp_in 4, ps_in 10, out 6, M = 2; N = 5, E = 8 (8 messages), F = 7.
    encoders = 2 * 5 * (5 * 8 + 64) + 2 * 8 * (4 * 8 + 64) + 2 * 7 * (10 * 8 + 64)
    decoder = 2 * 5 * (8 * 8 + 8 * 6)
    # ps: first layer's halves on N + F rows, second layer on N rows; node MLP on N rows
    ps_and_node = 2 * 64 * (2 * 5 + 7) + 2 * 5 * (16 * 8 + 64)
    # pp: first layer on E rows (plain) or 2N + E rows of h (concat), second on E/2 pairs
    pp_plain = 2 * (8 * 24 * 8 + 4 * 64)
    pp_concat = 2 * (2 * 5 * 64 + 8 * 64 + 4 * 64)
    assert encoders + decoder == 5712
    assert model(M=2, concat_trick="never").flops_per_step(5, 8, 7) == 5712 + 2 * (
        pp_plain + ps_and_node
    )
    assert model(M=2, concat_trick="always").flops_per_step(5, 8, 7) == 5712 + 2 * (
        pp_concat + ps_and_node
    )


@pytest.mark.parametrize(
    "kwargs, pairs, no_ps",
    [
        (dict(concat_trick="never"), PAIRS, False),
        (dict(concat_trick="always"), PAIRS, False),
        (dict(concat_trick="auto"), PAIRS, False),
        (dict(third_law=False, concat_trick="always"), PAIRS, False),
        (dict(num_materials=3, material_dim=2), PAIRS, False),
        (dict(), [], False),
        (dict(), PAIRS, True),
        (dict(use_surfaces=False), PAIRS, False),
        (dict(use_surfaces=False), [], False),
    ],
)
def test_flops_per_step_equals_measured_flops(kwargs, pairs, no_ps):
    net = model(**kwargs)
    g = graph(pairs=pairs)
    if no_ps:
        g = dict(g, ps_index=g["ps_index"][:, :0], ps_attr=g["ps_attr"][:0])
    material = torch.zeros(5, dtype=torch.long)
    # no_grad, not inference_mode: under inference_mode torch 2.4's counter misses most matrix
    # products (8 448 of 28 752 FLOPs here); under no_grad every torch version counts them all
    with FlopCounterMode(display=False) as counter, torch.no_grad():
        net(**g, material=material)
    expected = net.flops_per_step(5, g["pp_index"].shape[1], g["ps_index"].shape[1])
    assert counter.get_total_flops() == expected


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda g: dict(g, x=g["x"][:, :4]), "x must be"),
        (lambda g: dict(g, pp_attr=g["pp_attr"][:, :3]), "pp_attr"),
        (lambda g: dict(g, pp_index=g["pp_index"][:, :7], pp_attr=g["pp_attr"][:7]), "paired"),
        (lambda g: dict(g, pp_index=g["pp_index"].flip(1)[:, [0, 1, 2, 3, 5, 4, 6, 7]]), "paired"),
        (lambda g: dict(g, ps_attr=g["ps_attr"][:6]), "ps_attr"),
    ],
)
def test_bad_graph_input_gets_one_clear_error(change, match, monkeypatch):
    monkeypatch.setenv("PHYSGNN_CHECKS", "1")  # the layout check reads back: debug only
    with pytest.raises(ValueError, match=match):
        model()(**change(graph()))


def test_bad_material_input_and_config_errors(monkeypatch):
    net = model(num_materials=2, material_dim=3)
    with pytest.raises(ValueError, match="pass material"):
        net(**graph())
    with pytest.raises(IndexError):  # without the checks, the embedding's own error
        net(**graph(), material=torch.tensor([0, 1, 2, 0, 0]))
    monkeypatch.setenv("PHYSGNN_CHECKS", "1")  # the range check reads back: debug only
    with pytest.raises(ValueError, match="out of range"):
        net(**graph(), material=torch.tensor([0, 1, 2, 0, 0]))
    with pytest.raises(ValueError, match="material must be"):
        net(**graph(), material=torch.tensor([0, 1]))
    with pytest.raises(ValueError, match="num_materials"):
        model(num_materials=2)
    out = model()(**graph(), material=torch.tensor([0, 1, 2, 0, 0]))  # ignored, no embedding
    assert out.shape == (5, 6)


def test_reset_parameters_reinitialises_every_weight():
    net = model(num_materials=2, material_dim=3)
    before = {k: v.clone() for k, v in net.state_dict().items()}
    net.reset_parameters()
    for k, v in net.state_dict().items():
        assert not torch.equal(before[k], v), k
