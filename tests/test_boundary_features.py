"""GNS-style boundary features of LearnedSimulator: hand-built boxes, batching, config, loading."""

from __future__ import annotations

import math

import pytest
import torch
from handmade import make_state
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf
from simdata import REPORT_MODEL, STATS, batch, learned, trajectory
from torch.testing import assert_close
from torch_geometric.data import Batch

from physgnn import CONF_DIR
from physgnn.models.learned import LearnedSimulator
from physgnn.physics.scene import STATIC, WALL, make_plane
from physgnn.training.checks import check_arguments
from physgnn.training.runs import load_run

R = 2.0  # boundary_radius of these tests (the config default)
CONF = CONF_DIR


def make(**kwargs) -> LearnedSimulator:
    """The report's model with boundary features (model=gns builds on model=report)."""
    torch.manual_seed(0)
    args = dict(H=0, M=1, hidden=16, boundary_features=True, boundary_radius=R) | kwargs
    return learned(**(REPORT_MODEL | args))


def box(half: float) -> tuple[list, list]:
    """Plane rows and kinds of 4 walls at x = ±half, y = ±half facing inward (plus the ground
    that make_state adds)."""
    rows = [make_plane((x, 0, 5), (-x / half, 0, 0), (0, 1, 0), half, 5) for x in (half, -half)]
    rows += [make_plane((0, y, 5), (0, -y / half, 0), (1, 0, 0), half, 5) for y in (half, -half)]
    return rows, [WALL] * 4


def box_state(pos, radius=0.5, half: float = 5.0):
    rows, kinds = box(half)
    return make_state(pos, radius=radius, planes=rows, kinds=kinds)


def test_features_in_a_10_m_box_by_hand():
    # columns +x, −x, +y, −y, +z, −z: the +x column is the wall at x = −5 (normal +x), the +z
    # one the ground; h = distance from the sphere's surface, clipped at R = 2 and divided by R
    state = box_state([[4, 0, 1], [-4.25, 3.75, 0.5], [5.5, -4, 3]], radius=[0.5, 0.5, 0.25])
    expected = torch.tensor(
        [
            [1.0, 0.25, 1.0, 1.0, 0.25, 1.0],  # 0.5 m from the wall x = 5 and from the ground
            [0.125, 1.0, 1.0, 0.375, 0.0, 1.0],  # resting on the ground in a corner
            [1.0, 0.0, 0.375, 1.0, 1.0, 1.0],  # behind the wall x = 5: clipped to 0
        ]
    )
    assert_close(make().boundary_features(state), expected)


def test_sphere_far_from_every_plane_sees_all_ones():
    state = box_state([[0, 0, 50], [0.5, -0.5, 2.5]])  # 4.5 m from the walls, 2 m up
    assert_close(make().boundary_features(state), torch.ones(2, 6))


def test_tilted_and_downward_planes_go_to_their_closest_axis():
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    ramp = make_plane((0, 0, 0), (s, 0, c), (c, 0, -s), 3, 3)  # tilted 30° from +z: +z
    ceiling = make_plane((0, 0, 8), (0, 0, -1), (1, 0, 0), 9, 9)  # facing down: −z
    state = make_state([[0, 0, 2], [0, 0, 7]], planes=[ramp, ceiling], kinds=[STATIC, STATIC])
    up = min(2 * c - 0.5, 1.5) / R  # the ramp is nearer than the ground
    expected = torch.tensor([[1, 1, 1, 1, up, 1], [1, 1, 1, 1, 1, 0.25]])
    assert_close(make().boundary_features(state), expected)


def test_each_sphere_sees_only_the_planes_of_its_own_scene():
    big = box_state([[1, 1, 1], [4, 0, 3]], half=5.0)
    small = box_state([[1, 1, 1]], half=2.0)
    state = Batch.from_data_list([big, small])
    assert state.plane_batch.tolist() == [0] * 5 + [1] * 5
    expected = torch.tensor(
        [
            [1.0, 1.0, 1.0, 1.0, 0.25, 1.0],  # the walls of the small box are not its own
            [1.0, 0.25, 1.0, 1.0, 1.0, 1.0],
            [1.0, 0.25, 1.0, 0.25, 0.25, 1.0],  # 0.5 m from the walls x = 2 and y = 2
        ]
    )
    sim = make()
    got = sim.boundary_features(state)
    assert_close(got, expected)
    assert_close(got, torch.cat([sim.boundary_features(big), sim.boundary_features(small)]))


def test_no_planes_and_no_spheres():
    state = box_state([[0, 0, 1]])
    empty = state.clone()
    empty.planes, empty.plane_kind = state.planes[:0], state.plane_kind[:0]
    empty.plane_batch = state.plane_batch[:0]
    assert_close(make().boundary_features(empty), torch.ones(1, 6))
    none = box_state([[0, 0, 1]])
    none.pos, none.radius = none.pos[:0], none.radius[:0]
    assert make().boundary_features(none).shape == (0, 6)


def test_node_in_grows_by_6_only_when_enabled():
    plain, gns = make(H=2, boundary_features=False), make(H=2)
    assert plain.node_in == 6 * 3 + 2 and gns.node_in == plain.node_in + 6
    assert gns.network.node_encoder.lin1.in_features == gns.node_in
    state = batch([trajectory(3, seed=0)])
    x = gns.node_features(state)
    assert x.shape == (3, gns.node_in)
    assert_close(x[:, -6:], gns.boundary_features(state))


@pytest.mark.parametrize("model", ["report", "default"])
def test_default_features_are_unchanged(model):
    state = batch([trajectory(3, seed=1), trajectory(2, seed=2)])
    switches = REPORT_MODEL if model == "report" else {}
    plain = learned(H=2, M=1, hidden=16, **switches)
    assert not plain.inputs.boundary_features
    x = plain.node_features(state)
    assert x.shape == (5, 6 * 3 + 2 if model == "report" else 6 * 3 + 1 + 4)
    with_boundary = learned(H=2, M=1, hidden=16, boundary_features=True, **switches)
    assert torch.equal(with_boundary.node_features(state)[:, :-6], x)


def test_gns_style_model_runs_forward_and_backward():
    sim = make(third_law=False, use_surfaces=False)
    scenes = [box_state([[4, 0, 1], [4, 1, 1], [0, 0, 3]]), box_state([[1, 1, 1]], half=2.0)]
    state = Batch.from_data_list(scenes)  # one touching pair, both near a wall and the ground
    state.target_vel, state.target_angvel = torch.randn(4, 3), torch.randn(4, 3)
    state.pos.requires_grad_(True)
    pred, graph = sim.normalized_prediction(state)
    assert graph.pp_index.shape[1] == 2 and pred.shape == (4, 6)
    loss = (pred - sim.normalized_target(state)).pow(2).mean()
    loss.backward()
    grads = [p.grad for p in sim.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    weight = sim.network.node_encoder.lin1.weight.grad
    assert weight[:, -6:].abs().sum() > 0  # the boundary columns are trained
    assert torch.isfinite(state.pos.grad).all()


def test_bad_boundary_radius():
    with pytest.raises(ValueError, match="model.inputs.boundary_radius must be a number > 0"):
        make(boundary_radius=0.0)


@pytest.mark.parametrize("model", ["baseline", "gns"])
def test_config_keys_are_accepted(model):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        cfg = compose("train", overrides=[f"model={model}"])
    check_arguments(cfg)
    inputs = cfg.model.inputs
    assert inputs.boundary_features == (model == "gns") and inputs.boundary_radius == R
    sim = instantiate(cfg.model, stats=STATS)
    assert sim.inputs.boundary_features == (model == "gns") and sim.inputs.boundary_radius == R


def test_run_with_boundary_features_loads_back(tmp_path):
    sim = make(H=1, boundary_radius=1.5).eval()
    model = dict(_target_="physgnn.models.learned.LearnedSimulator", H=1, M=1, hidden=16)
    model |= REPORT_MODEL | dict(boundary_features=True, boundary_radius=1.5)
    (tmp_path / ".hydra").mkdir()
    OmegaConf.save(OmegaConf.create({"model": model}), tmp_path / ".hydra" / "config.yaml")
    (tmp_path / "checkpoints").mkdir()
    weights = {f"simulator.{k}": v for k, v in sim.state_dict().items()}
    torch.save({"state_dict": weights}, tmp_path / "checkpoints" / "last.ckpt")
    loaded, _, _ = load_run(tmp_path)
    assert loaded.inputs.boundary_features and loaded.inputs.boundary_radius == 1.5
    state = batch([trajectory(3, seed=5)], t=2, H=1)
    assert torch.equal(loaded(state)[0], sim(state)[0])
