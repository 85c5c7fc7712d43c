"""The engine state (model.inputs.engine_state): the engine's end-of-frame velocities as the
state, the frame's mean motion predicted apart; flight exact after a contact, an isolated
group's centre of mass exact for any weights."""

from __future__ import annotations

import copy
from functools import partial

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from simdata import STATS
from torch.testing import assert_close
from torch_geometric.data import Batch

from physgnn.data.pairs import PairDataset
from physgnn.data.state import SceneState, TrajectoryFrames, has_engine_velocities
from physgnn.evaluation.rollouts import energy_of, metrics_row
from physgnn.evaluation.runs import RunInfo
from physgnn.evaluation.simulate import scene_metrics
from physgnn.evaluation.stability import measure
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.oracles import sphere_scene
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.models.contact_inputs import gravity_share
from physgnn.models.learned import LearnedSimulator
from physgnn.models.options import ModelInputs
from physgnn.nn.epd import EncodeProcessDecode
from physgnn.physics import integrator
from physgnn.physics import quaternion as Q
from physgnn.rollout import VELOCITY, rollout
from physgnn.training.callbacks import RolloutCallback
from physgnn.training.layout import model_of_today
from physgnn.training.lit import LitSimulator, push_forward
from physgnn.training.losses import regime_weights

G = 9.81
ENGINE = STATS | {"substeps": 40}


def engine_model(M: int = 1, seed: int = 0) -> LearnedSimulator:
    """The default model on the engine state, H = 1, ``M`` blocks of 8 units, random weights."""
    torch.manual_seed(seed)
    network = partial(EncodeProcessDecode, M=M, hidden=8)
    return LearnedSimulator(ENGINE, H=1, network=network, inputs=ModelInputs(engine_state=True))


@pytest.fixture(scope="module")
def head_on():
    """Two spheres (r 0.5 m) meeting head-on 50 m up at 4 m/s each, 16 frames at dt 0.1 s:
    pybullet at 40 substeps."""
    scene = sphere_scene([[-2.0, 0, 50.0], [2.0, 0, 50.0]], vel=[[4.0, 0, 0], [-4.0, 0, 0]])
    scene.n_frames = 16
    return simulate(scene, {"substeps": 40})


def test_gravity_share_follows_the_engines_substeps():
    assert gravity_share({"substeps": 1}) == 1.0
    assert gravity_share({"substeps": 40}) == pytest.approx(41 / 80)
    assert gravity_share({}) == gravity_share({"substeps": 0}) == 0.5  # the exact parabola


def test_frames_carry_the_engines_velocities_and_the_mean_motion_as_targets(head_on):
    assert has_engine_velocities(head_on)
    frames = TrajectoryFrames(head_on, engine_state=True)
    s = frames.state(5, 1, future=2)
    assert_close(s.vel[:, 0], torch.as_tensor(head_on.vel[5]))
    assert_close(s.target_vel, torch.as_tensor(head_on.vel[6]))
    pos = torch.as_tensor(head_on.pos)
    assert_close(s.target_mean_vel, (pos[6] - pos[5]) / 0.1)
    assert_close(s.future_vel[:, 1], torch.as_tensor(head_on.vel[7]))
    fd = TrajectoryFrames(head_on)  # the report's state: finite differences
    assert_close(fd.state(5, 1).vel[:, 0], (pos[5] - pos[4]) / 0.1)
    # the pair tables give the same state as the frames
    pairs = PairDataset([head_on], 1, future=0, engine_state=True)
    row = int((pairs.pairs[:, 1] == 5).nonzero()[0])
    batch = pairs.batch(torch.tensor([row]))
    for key in ("vel", "target_vel", "target_mean_vel", "target_mean_angvel"):
        assert_close(batch[key], s[key])


def test_data_with_positions_only_keeps_finite_differences(head_on):
    imported = copy.copy(head_on)
    imported.attrs = {k: v for k, v in head_on.attrs.items() if k != "engine"}
    frames = TrajectoryFrames(imported, engine_state=True)
    assert torch.equal(frames.vel, frames.mean_vel)


def test_flight_after_a_contact_is_exact_from_the_engine_state(head_on):
    """One step from every truth frame: once the spheres part (out of reach), the random-weight
    model's move and end velocity are the truth's to float rounding (the FD state is not)."""
    sim = engine_model().eval()
    frames = TrajectoryFrames(head_on, engine_state=True)
    pos = torch.as_tensor(head_on.pos)
    free = 0
    for t in range(1, 15):
        state = Batch.from_data_list([frames.state(t, 1)])
        graph = sim.graph_builder(state)
        step = sim.step(state, graph)
        if bool(step.reach.any()):
            continue
        free += 1
        moved, _ = integrator.move(state.pos, state.quat, step.mean_vel, step.mean_angvel, 0.1)
        assert_close(moved, pos[t + 1], atol=2e-5, rtol=0)
        assert_close(step.vel, torch.as_tensor(head_on.vel[t + 1]), atol=2e-5, rtol=0)
    assert free >= 8  # flight before and after the impact
    # the x velocity reversed in the impact: the flight after it starts from the engine's v
    assert float(head_on.vel[15][0, 0]) < 0 < float(head_on.vel[0][0, 0])


def test_an_isolated_groups_centre_of_mass_moves_ballistically_for_any_weights():
    """Three touching spheres of different masses 30 m up, no plane in reach: Σ m Δp equals
    the ballistic displacement of the centre of mass, Σ m v_{t+1} its momentum plus M g dt."""
    pos = torch.tensor([[0.0, 0, 30], [1.0, 0, 30], [0.5, 0.85, 30]])
    vel = torch.tensor([[1.0, 0, 0], [-1.0, 0.5, 0], [0.0, -2.0, 1.0]])
    mass = torch.tensor([1.0, 3.0, 7.0])
    state = SceneState(
        pos=pos,
        quat=Q.identity(3),
        vel=vel[:, None].repeat(1, 2, 1),
        angvel=torch.zeros(3, 2, 3),
        radius=torch.full((3,), 0.5),
        mass=mass,
        material=torch.zeros(3, dtype=torch.long),
        material_params=torch.tensor([[0.5, 0.5, 0.0, 0.0]]).repeat(3, 1),
        planes=torch.tensor([[0.0, 0, 0, 0, 0, 1, 1, 0, 0, 0, 0]]),
        plane_kind=torch.zeros(1, dtype=torch.long),
        plane_materials=torch.tensor([[1.0, 1.0, 0.0, 0.0]]),
        plane_batch=torch.zeros(1, dtype=torch.long),
        dt=torch.tensor([0.1]),
        effects=torch.ones(1, 5, dtype=torch.bool),
    )
    state = Batch.from_data_list([state])
    for seed in range(3):
        sim = engine_model(M=2, seed=seed).eval()
        graph = sim.graph_builder(state)
        step = sim.step(state, graph)
        assert bool(step.reach.all()) and graph.pp_index.shape[1] == 6
        total = mass.sum()
        centre_move = (mass[:, None] * step.mean_vel * 0.1).sum(0) / total
        v_com = (mass[:, None] * vel).sum(0) / total
        share = 41 / 80
        expected = 0.1 * v_com + torch.tensor([0, 0, -G * 0.01 * share])
        assert_close(centre_move, expected, atol=1e-5, rtol=0)
        momentum = (mass[:, None] * step.vel).sum(0)
        assert_close(momentum, total * (v_com + torch.tensor([0, 0, -G * 0.1])), atol=1e-4, rtol=0)
        assert not torch.allclose(step.mean_vel, step.vel)  # the network moves them apart


def test_the_rollout_moves_by_the_mean_and_keeps_the_end_velocity():
    pos, quat = torch.zeros(2, 3), Q.identity(2)
    hist = torch.ones(2, 2, 3)
    end, mean = torch.tensor([[1.0, 2, 3], [0, 0, -1]]), torch.tensor([[2.0, 0, 0], [0, 1, 0]])
    spin = torch.tensor([[0.0, 0, 1.0], [0, 0, 0]])
    dt = torch.full((2,), 0.5)
    p, q, v, w = integrator.step(pos, quat, hist, hist, end, spin, dt, mean=(mean, spin))
    assert_close(p, 0.5 * mean)
    assert_close(v[:, 0], end)
    assert_close(v[:, 1], hist[:, 0])
    assert_close(Q.angular_velocity(quat, q, 0.5), spin)  # the exact rotation of ω̄·dt


def test_training_losses_and_push_forward_run_on_the_engine_state(head_on):
    sim = engine_model()
    lit = LitSimulator(sim, lambda params: torch.optim.Adam(params, lr=1e-3))
    pairs = PairDataset([head_on], 1, future=2, engine_state=True)
    batch = pairs.batch(torch.arange(4))
    losses = lit.losses(batch)
    assert torch.isfinite(losses["loss"]) and float(losses["loss_mse"].detach()) > 0
    losses["loss"].backward()
    ahead = push_forward(batch, sim, 2)
    assert_close(ahead.target_vel, batch.future_vel[:, 2])
    assert ahead.target_mean_vel.shape == batch.pos.shape


def test_runs_before_the_engine_state_load_with_finite_differences():
    model = {"_target_": "physgnn.models.learned.LearnedSimulator", "H": 2}
    model |= {"network": {"M": 1}, "inputs": {"contact_features": True}, "contacts": {}}
    assert model_of_today(OmegaConf.create(model)).inputs.engine_state is False
    today = dict(model, inputs={"engine_state": True})
    assert model_of_today(OmegaConf.create(today)).inputs.engine_state is True
    assert np.isclose(gravity_share(ENGINE), 0.5125)


def test_regime_weights_give_moving_contacts_their_share_and_keep_the_sum():
    state = SceneState(
        pos=torch.zeros(4, 3),
        vel=torch.zeros(4, 1, 3),
        radius=torch.full((4,), 0.5),
        dt=torch.tensor([0.1]),
        effects=torch.ones(1, 5, dtype=torch.bool),
    )
    ballistic = torch.tensor([0.0, 0, -0.981])
    state.target_vel = ballistic.repeat(4, 1)
    state.target_vel[0] = torch.tensor([2.0, 0, 1.0])  # a bounce: a moving contact
    state.target_angvel = torch.zeros(4, 3)
    sim = engine_model()
    weights = regime_weights(state, sim, None, 0.5, 0.05)
    assert_close(weights, torch.tensor([2.0, 2 / 3, 2 / 3, 2 / 3]))
    assert_close(weights.sum(), torch.tensor(4.0))
    # already above its share, or nothing else counted: every counted sphere weighs 1
    assert_close(regime_weights(state, sim, None, 0.2, 0.05), torch.ones(4))
    counted = torch.tensor([True, False, False, False])
    assert_close(regime_weights(state, sim, counted, 0.5, 0.05), torch.tensor([1.0, 0, 0, 0]))
    # a sphere the truth brings to rest is no moving contact
    state.target_vel[0] = 0.0
    assert_close(regime_weights(state, sim, None, 0.5, 0.05), torch.ones(4))


def test_rollouts_of_the_engine_state_with_sleeping_and_the_constraint_stage(head_on):
    """The wrappers pass the four-tensor answer on: a rollout with sleeping spheres and one with
    the constraint stage run, finite, starting from the engine's velocities."""
    sim = engine_model().eval()
    sim.effects_trained.fill_(True)  # as if trained on every effect: no rollout warning
    for wrapped, sleep in ((sim, True), (ConstrainedSimulator(sim, 2), False)):
        (pred,) = rollout(wrapped, [head_on], n_frames=8, sleep=sleep)
        assert pred.pos.shape == (8, 2, 3) and np.isfinite(np.asarray(pred.pos)).all()
        assert_close(torch.as_tensor(pred.pos[:2]), torch.as_tensor(head_on.pos[:2]))
    answer = ConstrainedSimulator(sim, 2)(
        Batch.from_data_list([TrajectoryFrames(head_on, True).state(1, 1)])
    )
    assert len(answer) == 4


def test_an_engine_state_rollout_of_positions_only_says_so_in_one_warning(head_on):
    imported = copy.copy(head_on)
    imported.attrs = {k: v for k, v in head_on.attrs.items() if k != "engine"}
    sim = engine_model().eval()
    sim.effects_trained.fill_(True)
    with pytest.warns(UserWarning, match="hold no engine velocities"):
        rollout(sim, [imported], n_frames=4)


def test_every_rows_energy_is_measured_from_finite_differences_whatever_the_models_state(
    head_on,
):
    """An engine-state rollout keeps the model's end-of-frame velocities (and says so), while
    make eval, simulate and the study measure its energy, as the truth's and pybullet's, from
    finite differences of the positions: the same rollout with FD velocities scores the same."""
    [pred] = rollout(engine_model(), [head_on])
    fd = pred.with_finite_velocities()
    assert pred.attrs["velocity"] == VELOCITY[True]
    assert not np.allclose(pred.vel[2:], fd.vel[2:])  # the model's own, not the FD ones
    run = RunInfo(name="m", experiment="default", overrides="", seed=0)
    own, alike = (
        metrics_row(run, "test", head_on, pred, 0.0),
        metrics_row(run, "test", head_on, fd, 0.0),
    )
    assert own["energy_gain"] == alike["energy_gain"]
    assert_close(energy_of(head_on, pred), energy_of(head_on, fd))
    assert measure(head_on, pred)["energy_gain"] == measure(head_on, fd)["energy_gain"]
    assert scene_metrics(head_on, pred, 0.0) == scene_metrics(head_on, fd, 0.0)
    [logged], _ = RolloutCallback(ood=False).rollout_metrics(engine_model(), [head_on])
    assert logged["energy_gain"] == alike["energy_gain"]  # training's val/energy_gain too
