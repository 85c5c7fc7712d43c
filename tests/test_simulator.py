"""LearnedSimulator: normalisation, target round trip, rotation switch, invariances, buffers."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest
import torch
from hydra.utils import get_class, instantiate
from omegaconf import OmegaConf
from simdata import MODEL_KEYS, REPORT_MODEL, STATS, batch, learned, trajectory
from torch.testing import assert_close

from physgnn import CONF_DIR
from physgnn.graph.builder import GraphBuilder
from physgnn.models.learned import LearnedSimulator, StatsError
from physgnn.models.options import ContactHandling, ModelInputs
from physgnn.models.profiling import StepTimer
from physgnn.nn.epd import EncodeProcessDecode
from physgnn.physics.scene import Effects
from physgnn.training.layout import dotted_model

MODEL_CONF = Path(CONF_DIR) / "model"


def make(**kwargs) -> LearnedSimulator:
    torch.manual_seed(0)
    args = dict(H=2, M=2, hidden=16) | kwargs
    return learned(**args)


def report(**kwargs) -> LearnedSimulator:
    """The report's model (tests/simdata.py, REPORT_MODEL)."""
    return make(**(REPORT_MODEL | kwargs))


def defaults_of(cls) -> dict:
    params = inspect.signature(cls).parameters.values()
    return {p.name: p.default for p in params if p.default is not inspect.Parameter.empty}


# The nodes of the model config, the constructor each is built with and that constructor's
# arguments the config leaves to the code (the widths the simulator sets; an evaluation detail).
LEFT_TO_CODE = {"widths", "concat_trick"}
NODES = {
    "network": (EncodeProcessDecode, LEFT_TO_CODE),
    "graph": (GraphBuilder, set()),
    "inputs": (ModelInputs, set()),
    "contacts": (ContactHandling, set()),
}


def test_constructor_defaults_are_the_default_model_and_report_model_is_the_reports():
    baseline = OmegaConf.to_container(OmegaConf.load(MODEL_CONF / "baseline.yaml"))
    assert get_class(baseline.pop("_target_")) is LearnedSimulator
    for node, (cls, left) in NODES.items():
        keys = baseline.pop(node)
        assert get_class(keys.pop("_target_")) is cls and keys.pop("_partial_", node != "network")
        assert keys == {k: v for k, v in defaults_of(cls).items() if k not in left}, node
    groups = {"inputs": ModelInputs(), "contacts": ContactHandling()}
    assert defaults_of(LearnedSimulator) == baseline | {"network": None, "graph": None} | groups
    own = OmegaConf.load(MODEL_CONF / "report.yaml")
    own.pop("defaults")
    default = OmegaConf.load(MODEL_CONF / "baseline.yaml")
    composed = dotted_model(OmegaConf.merge(default, own))
    report_keys = {".".join(MODEL_KEYS.get(k, (k,))): v for k, v in REPORT_MODEL.items()}
    assert dotted_model(default) | report_keys | {"H": 2} == composed  # the report's history


def test_default_simulator_is_the_default_config_model():
    cfg = OmegaConf.load(MODEL_CONF / "baseline.yaml")
    torch.manual_seed(0)
    built = instantiate(cfg, stats=STATS).state_dict()
    torch.manual_seed(0)
    plain = LearnedSimulator(STATS).state_dict()
    assert built.keys() == plain.keys()
    assert all(torch.equal(built[k], plain[k]) for k in built)


def test_default_and_report_widths():
    default, old = make(H=2), report(H=2)
    # node: 6(H+1) velocities, radius, 4 material values (no mass); the report's: radius, mass
    assert (default.node_in, old.node_in) == (6 * 3 + 1 + 4, 6 * 3 + 2)
    # pp: [p_i − p_j, |p_i − p_j|], gap, normal and tangential relative speed, 3 relative
    # velocities, 2 radii, the mass ratio, 2 pair materials; the report's: the first 4
    assert (default.network.pp_in, old.network.pp_in) == (4 + 5 + 9 + 1 + 2, 4)
    # ps: [v, n, δ, h], clearance, normal and tangential speed, the sphere's restitution and
    # friction; the report's: the first 10
    assert (default.network.ps_in, old.network.ps_in) == (15, 10)
    outputs = [m.network.decoder.lin2.out_features for m in (default, old)]
    # Δv, Δω of the end velocities, of the frame's mean motion (engine state), the rest logit
    assert outputs == [13, 6]
    assert default.network.pair_decoder.mlp.out_dim == 12 and old.network.pair_decoder is None
    assert [m.network.aggregation for m in (default, old)] == ["mean", "sum"]
    assert [m.graph_builder.connectivity for m in (default, old)] == ["approach", "vi"]


def test_the_docstrings_node_input_count_is_the_default_models():
    """LearnedSimulator's docstring gives the default inputs' node count as ``6·(H+1) + c`` and
    its value at the default H: both are the widths of the models built, blocks and network."""
    doc = " ".join(LearnedSimulator.__doc__.split())
    constant = int(re.search(r"``6·\(H\+1\) \+ (\d+)`` numbers with the default inputs", doc)[1])
    count, H = map(int, re.search(r"(\d+) for the default model, H = (\d+)", doc).groups())
    default = instantiate(OmegaConf.load(MODEL_CONF / "baseline.yaml"), stats=STATS)
    state = batch([trajectory(3, seed=0)], H=H)
    widths = default.node_in, default.network.node_in, default.node_features(state).shape[1]
    assert default.H == H and widths == (count, count, count)
    for h in range(4):
        assert make(H=h).node_in == 6 * (h + 1) + constant
    assert default.node_layout.names == ("vel", "angvel", "radius", "material")


def test_forward_shapes_and_timings():
    sim, timer = make(), StepTimer()  # timing is opt-in, outside the simulator
    state = batch([trajectory(3, seed=0), trajectory(5, seed=1)])
    with timer.watch(sim):
        vel, angvel, mean_vel, mean_angvel = timer.predict(sim, state)  # the engine state's
    assert vel.shape == mean_vel.shape == (8, 3) and angvel.shape == mean_angvel.shape
    assert torch.isfinite(vel).all() and torch.isfinite(angvel).all()
    assert timer.timings["graph"] > 0 and timer.timings["network"] > 0
    timer.reset()
    assert {k: timer.timings[k] for k in ("graph", "network")} == {"graph": 0.0, "network": 0.0}
    assert sim.graph_builder.__class__.__name__ == "GraphBuilder"  # unwrapped again


def test_node_features_by_hand():
    sim = report(H=1)
    state = batch([trajectory(2, seed=3)], t=4, H=3)  # a longer history than the model's
    x = sim.node_features(state)
    assert x.shape == (2, 6 * 2 + 2)
    mean, std = torch.tensor(STATS["vel"]["mean"]), torch.tensor(STATS["vel"]["std"])
    assert_close(x[0, 0:3], (state.vel[0, 0] - mean) / std)
    assert_close(x[0, 3:6], (state.vel[0, 1] - mean) / std)
    assert_close(x[1, 6:9], state.angvel[1, 0] / 0.5)
    assert_close(x[1, 12], (state.radius[1] - 0.5) / 0.1)
    assert_close(x[1, 13], (state.mass[1] - 2.0) / 0.5)


def test_default_node_features_hold_no_mass():
    sim = make(H=1)
    state = batch([trajectory(2, seed=3)], t=4, H=3)
    x = sim.node_features(state)
    assert x.shape == (2, 6 * 2 + 1 + 4)
    assert_close(x[1, 12], (state.radius[1] - 0.5) / 0.1)
    heavy = state.clone()
    heavy.mass = state.mass * 37.0
    assert torch.equal(sim.node_features(heavy), x)


def test_edge_features_scaled_by_length_and_velocity_std():
    sim = report(length_scale=2.0)
    state = batch([trajectory(3, seed=0)])
    graph = sim.graph_builder(state)
    pp, ps = sim.edge_features(graph)
    assert_close(pp, graph.pp_attr / 2.0)
    assert_close(ps[:, :3], graph.ps_attr[:, :3] / torch.tensor([1.0, 2.0, 4.0]))
    assert_close(ps[:, 3:6], graph.ps_attr[:, 3:6])
    assert_close(ps[:, 6:], graph.ps_attr[:, 6:] / 2.0)


def test_default_length_scale_is_mean_diameter():
    assert float(make().length_scale) == pytest.approx(1.0)


def test_target_round_trip_gives_ground_truth():
    sim = report()
    state = batch([trajectory(4, seed=2)])
    vel, angvel = sim.to_physical(state, sim.normalized_target(state))
    assert_close(vel, state.target_vel)
    assert_close(angvel, state.target_angvel)


def test_target_round_trip_of_the_default_model_in_reach_and_not_at_rest():
    sim = make()
    state = batch([trajectory(4, seed=2)])  # positions only: the mean targets are the ends
    target = sim.normalized_target(state)
    assert target.shape == (4, 12)
    pred = torch.cat([target, torch.full((4, 1), -1.0)], 1)  # rest logit < 0: not at rest
    vel, angvel, mean_vel, mean_angvel = sim.motion(state, pred, torch.ones(4, dtype=torch.bool))
    for got in (vel, mean_vel):
        assert_close(got, state.target_vel)
    for got in (angvel, mean_angvel):
        assert_close(got, state.target_angvel)
    with pytest.raises(ValueError, match="needs the spheres in reach"):
        sim.to_physical(state, pred)


def test_zero_output_means_mean_change():
    sim = report()
    state = batch([trajectory(3, seed=2)])
    vel, angvel = sim.to_physical(state, torch.zeros(3, 6))
    assert_close(vel, state.vel[:, 0] + torch.tensor([0.0, 0.0, -0.9]))
    assert_close(angvel, state.angvel[:, 0])


def test_rotation_off_keeps_angular_velocity():
    sim = report()  # the default model's gravity prior would keep every ω in free flight
    still = trajectory(3, seed=4, effects=Effects(rotation=False))
    state = batch([trajectory(2, seed=5), still])
    _, angvel = sim(state)
    assert torch.equal(angvel[2:], state.angvel[2:, 0])
    assert not torch.equal(angvel[:2], state.angvel[:2, 0])


@pytest.mark.parametrize("gns_style", [False, True])
def test_horizontal_translation_invariance(gns_style):
    """Also for the GNS-style model, whose boundary distances move with the planes."""
    sim = make(boundary_features=True, use_surfaces=False) if gns_style else make()
    state = batch([trajectory(4, seed=6)])
    moved = state.clone()
    shift = torch.tensor([3.5, -2.0, 0.0])
    moved.pos = state.pos + shift
    moved.planes = state.planes.clone()
    moved.planes[:, :3] += shift
    for a, b in zip(sim(state), sim(moved), strict=True):
        assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_checkpoint_is_self_contained():
    sim = make(length_scale=0.7)
    sim.effects_trained.fill_(True)
    sd = sim.state_dict()
    assert "effects_trained" in sd and "delta_vel_std" in sd
    stats = LearnedSimulator.stats_from_state_dict(sd)
    assert stats["delta_vel"]["std"] == pytest.approx(STATS["delta_vel"]["std"])
    assert stats["mass"]["mean"] == pytest.approx(2.0)
    twin = learned(stats, H=2, M=2, hidden=16)
    twin.load_state_dict(sd)
    state = batch([trajectory(3, seed=7)])
    assert_close(twin(state)[0], sim(state)[0])
    assert bool(twin.effects_trained.all())


def test_missing_stats_is_one_clear_line():
    bad = {k: v for k, v in STATS.items() if k != "delta_angvel"}
    with pytest.raises(StatsError, match=r"lack 'delta_angvel.mean'"):
        LearnedSimulator(bad)
    bad = dict(STATS, vel={"mean": [0.0, 0.0], "std": [1.0, 1.0, 1.0]})
    with pytest.raises(StatsError, match=r"'vel.mean' has shape \(2,\)"):
        LearnedSimulator(bad)


def test_history_mismatch_raises():
    sim = make(H=3)
    with pytest.raises(ValueError, match="needs 4"):
        sim(batch([trajectory(2, seed=0)], t=3, H=1))


def test_material_embedding_changes_the_prediction(monkeypatch):
    # the report's model: the default one's gravity prior ignores the network in free flight
    sim = report(num_materials=3, material_dim=4)
    state = batch([trajectory(3, seed=9)])
    before = sim(state)[0]
    state.material = torch.tensor([2, 1, 0])
    assert not torch.equal(sim(state)[0], before)
    state.material = torch.tensor([0, 0, 3])
    monkeypatch.setenv("PHYSGNN_CHECKS", "1")  # the range check reads back: debug only
    with pytest.raises(ValueError, match="material id 3 out of range"):
        sim(state)
