"""The edge contract (physgnn/graph/edges.py): named blocks that tile every layout, the
builder and the model writing exactly the contract's widths and blocks for every option
combination, and the one plane-reach rule with gravity's fall."""

from __future__ import annotations

import inspect
import itertools

import pytest
import torch
from handmade import make_state
from simdata import batch, learned, trajectory
from torch.testing import assert_close

from physgnn.graph.builder import GraphBuilder
from physgnn.graph.edges import (
    PP,
    PP_CONTACT,
    PS,
    PS_CONTACT,
    PS_MATERIAL,
    Layout,
    pp_inputs,
    ps_inputs,
)
from physgnn.nn.epd import Widths

BOOLS = (False, True)
OPTIONS = [
    "relative_pairs",
    "mass_ratio",
    "material_features",
    "contact_features",
    "plane_materials",
]


def every_layout() -> list[Layout]:
    layouts = [PP, PS, PP_CONTACT, PS_CONTACT, PS_MATERIAL]
    flags = itertools.product((1, 3), BOOLS, BOOLS, BOOLS, BOOLS)
    layouts += [pp_inputs(*f) for f in flags]
    return layouts + [ps_inputs(*f) for f in itertools.product(BOOLS, BOOLS)]


def test_the_blocks_tile_every_layout_with_no_gap_or_overlap():
    for layout in every_layout():
        columns = range(layout.width)
        covered = [c for name in layout.names for c in columns[layout.slice(name)]]
        assert covered == list(columns), layout


def test_the_widths_by_hand():
    assert (PP.width, PS.width) == (4, 10)
    assert pp_inputs(3, False, False, False, False).width == 4  # the report's
    assert pp_inputs(3, False, False, False, True).width == 4 + 2
    assert pp_inputs(3, True, True, True, True).width == 4 + 5 + 9 + 1 + 2  # the default's
    assert ps_inputs(True, True).width == 10 + 3 + 2
    # the network's own defaults are the graph's blocks (nn imports nothing of physgnn)
    defaults = inspect.signature(Widths).parameters
    assert (defaults["pp_in"].default, defaults["ps_in"].default) == (PP.width, PS.width)


def test_blocks_are_read_and_written_by_name_only():
    attr = torch.arange(20.0).reshape(2, 10)
    assert_close(PS.take(attr, "height"), attr[:, 9:10])
    parts = {name: PS.take(attr, name) for name in PS.names}
    assert torch.equal(PS.join(parts), attr)
    with pytest.raises(ValueError, match="the layout has"):
        PS.join({k: v for k, v in parts.items() if k != "normal"})
    with pytest.raises(ValueError, match="'normal' has 2 columns, not 3"):
        PS.join(parts | {"normal": attr[:, :2]})
    with pytest.raises(KeyError, match="no edge block 'gap'"):
        PS.slice("gap")
    with pytest.raises(ValueError, match="unique names"):
        PS + PS_MATERIAL + PS_MATERIAL


@pytest.mark.parametrize("H", [0, 2])
def test_builder_and_model_write_the_contracts_blocks_for_every_option(H):
    state = batch([trajectory(n=12, seed=s) for s in range(3)], H=H)
    graph = GraphBuilder("vi")(state)
    assert graph.pp_attr.shape == (graph.pp_index.shape[1], PP.width)
    assert graph.ps_attr.shape == (graph.ps_index.shape[1], PS.width)
    assert graph.pp_index.shape[1] > 0 and graph.ps_index.shape[1] > 0
    radius = state.radius
    for values in itertools.product(BOOLS, repeat=len(OPTIONS)):
        options = dict(zip(OPTIONS, values, strict=True))
        sim = learned(H=H, M=1, hidden=8, **options)
        pp, ps = sim.edge_features(graph, state)
        pp_layout, ps_layout = sim.pp_layout, sim.ps_layout
        assert (pp.shape[1], ps.shape[1]) == (pp_layout.width, ps_layout.width)
        assert (sim.network.pp_in, sim.network.ps_in) == (pp_layout.width, ps_layout.width)
        scale = sim.length_scale
        distance = PP.take(graph.pp_attr, "distance") / scale
        assert_close(pp_layout.take(pp, "distance"), distance, rtol=0, atol=0)
        assert_close(ps_layout.take(ps, "normal"), PS.take(graph.ps_attr, "normal"))
        src, dst = graph.pp_index
        if options["relative_pairs"]:
            radii = torch.stack([radius[dst], radius[src]], 1) / scale
            assert_close(pp_layout.take(pp, "radii"), radii, rtol=0, atol=0)
        if options["contact_features"]:
            own = radius[graph.ps_index[1]][:, None]
            clearance = (PS.take(graph.ps_attr, "height") - own) / scale
            assert_close(ps_layout.take(ps, "clearance"), clearance, rtol=0, atol=0)
        if options["plane_materials"] and options["material_features"]:
            coefficients = state.material_params[graph.ps_index[1], :2]  # planes of 1 and 1
            assert_close(ps_layout.take(ps, "material"), coefficients, rtol=0, atol=0)


@pytest.mark.parametrize("connectivity", ["approach", "vi", "epsilon"])
def test_the_plane_reach_counts_gravitys_fall_once_under_every_rule(connectivity):
    # a sphere at rest above the ground: within the frame it falls g·dt² = 0.0981 m (dt = 0.1
    # s), and ε = 0.01, so it may touch the ground iff its clearance is <= 0.1081 m
    builder = GraphBuilder(connectivity, epsilon=0.01)
    for clearance, touches in [(0.1080, True), (0.1082, False)]:
        state = make_state([[0.0, 0.0, 0.5 + clearance]], radius=0.5, dt=0.1)
        sphere, normal = torch.tensor([0]), state.planes[:1, 3:6]
        gap = torch.tensor([clearance], dtype=torch.float64)
        args = state, sphere, normal, gap, builder.allowance(state)
        assert builder.touches_plane(*args).tolist() == [touches], clearance
        # the edge rule alone: only approach's ballistic velocity counts the fall
        linked = builder.plane_within_reach(*args).tolist()
        assert linked == [touches if connectivity == "approach" else False]
