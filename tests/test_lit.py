"""LitSimulator: energy term by hand, masked MSE, noise only in training, non-finite loss."""

from __future__ import annotations

import functools

import lightning as L
import pytest
import torch
from handmade import scene
from lightning.pytorch.callbacks import Callback, ModelCheckpoint
from simdata import REPORT_MODEL, batch, learned, trajectory
from torch.testing import assert_close
from torch_geometric.data import Batch
from torch_geometric.loader import DataLoader

from physgnn.data.state import SceneState
from physgnn.errors import ConfigError
from physgnn.models.capture import ShapeBoundCall
from physgnn.physics.scene import Effects
from physgnn.training.finite import NonFiniteLossError
from physgnn.training.lit import LitSimulator
from physgnn.training.losses import energy_increase, masked_mse, rest_loss
from physgnn.training.noise import add_noise, noise_seed, regime_scale
from physgnn.training.recipe import Compile, InputNoise, LossTerms, PushForward

ADAM = functools.partial(torch.optim.Adam, lr=1e-3)


def make_lit(model: dict | None = None, **kwargs) -> LitSimulator:
    """The default model (or ``model``'s switches) with H = 1, M = 1, 8 hidden units."""
    torch.manual_seed(0)
    sim = learned(H=1, M=1, hidden=8, **(model or {}))
    return LitSimulator(sim, ADAM, **kwargs)


def one_sphere(z: float, vel) -> SceneState:
    """One sphere (r 0.5 m, m 2 kg) at height z with velocity ``vel``; dt 0.1 s."""
    v = torch.tensor([vel], dtype=torch.float32)
    return SceneState(
        pos=torch.tensor([[0.0, 0.0, z]]),
        quat=torch.tensor([[1.0, 0, 0, 0]]),
        vel=v[:, None].repeat(1, 2, 1),
        angvel=torch.zeros(1, 2, 3),
        radius=torch.tensor([0.5]),
        mass=torch.tensor([2.0]),
        dt=torch.tensor([0.1]),
    )


def test_energy_increase_by_hand_one_sphere():
    state = one_sphere(2.0, [1.0, 0.0, 0.0])
    # v̂ = (2, 0, 3): kinetic 0.5·2·(4 + 9) − 0.5·2·1 = 12 J; the sphere rises 0.1·3 = 0.3 m:
    # potential + 2·9.81·0.3 J. Divided by the weight 2·9.81 N.
    gain = energy_increase(state, torch.tensor([[2.0, 0.0, 3.0]]))
    assert_close(gain, torch.tensor([(12.0 + 2 * 9.81 * 0.3) / (2 * 9.81)]))
    # slowing down and falling loses energy: no penalty
    assert_close(energy_increase(state, torch.tensor([[0.5, 0.0, -1.0]])), torch.zeros(1))


def test_energy_increase_per_scene_of_a_batch():
    state = batch([trajectory(2, seed=0), trajectory(3, seed=1)])
    assert_close(energy_increase(state, state.target_vel), torch.zeros(2))  # free fall loses
    faster = state.target_vel.clone()
    faster[2:] *= 3.0
    gain = energy_increase(state, faster)
    assert gain[0] == 0 and gain[1] > 0


def test_masked_mse_by_hand():
    pred, target = torch.zeros(2, 6), torch.ones(2, 6)
    target[1, 3:] = 5.0
    assert_close(masked_mse(pred, target, torch.tensor([True, False])), torch.tensor(1.0))
    assert_close(
        masked_mse(pred, target, torch.tensor([True, True])), torch.tensor((6 + 3 + 75) / 12)
    )


def test_energy_term_enters_the_loss_with_lambda():
    # the report's model: no gravity prior, so the flying spheres are the network's (mse > 0)
    state = batch([trajectory(3, seed=2)])
    plain = make_lit(REPORT_MODEL, loss=LossTerms(lambda_energy=0.0, lambda_contact=0.0))
    weighted = make_lit(REPORT_MODEL, loss=LossTerms(lambda_energy=0.5, lambda_contact=0.0))
    a, b = plain.losses(state), weighted.losses(state)
    assert float(a["loss_mse"].detach()) > 0
    assert_close(a["loss"], a["loss_mse"])
    assert_close(b["loss"], b["loss_mse"] + 0.5 * b["loss_energy"])
    assert_close(a["loss_energy"], b["loss_energy"])
    assert_close(a["energy_share"], torch.tensor(0.0))
    assert_close(b["energy_share"], 0.5 * b["loss_energy"] / b["loss"])


def test_noise_only_in_training_shaped_like_a_rollout_with_correcting_targets():
    # the same noise for every sphere, and no contact noise (which moves positions)
    lit = make_lit(noise=InputNoise(std=0.1, rest_scale=1.0, contact_depth=0.0))
    still = trajectory(40, seed=4, effects=Effects(rotation=False))
    state = batch([trajectory(40, seed=3), still])
    seen = []
    original = lit.simulator.network_prediction
    lit.simulator.network_prediction = lambda s, g, *a: seen.append(s) or original(s, g, *a)
    lit.log = lambda *args, **kwargs: None
    lit.validation_step(state, 0)
    lit.training_step(state, 0)
    clean, noisy = seen
    assert torch.equal(clean.pos, state.pos) and torch.equal(clean.vel, state.vel)
    dt = state.scene_dt[:, None]
    dv, dp = noisy.vel - state.vel, noisy.pos - state.pos
    # the noisy position and velocities are finite differences of one another
    assert_close(dp, dt * dv.sum(1))
    # σ·std(v) at the latest velocity (random walk over the H + 1 = 2 entries)
    assert dv[:, 0, 2].std().item() == pytest.approx(0.1 * 4.0, rel=0.25)
    # the target brings the noisy position back onto the true next position
    assert_close(noisy.pos + dt * noisy.target_vel, state.pos + dt * state.target_vel)
    assert torch.equal(noisy.target_angvel, state.target_angvel)
    assert_close(noisy.quat.norm(dim=-1), torch.ones(80))
    assert not torch.equal(noisy.quat[:40], state.quat[:40])
    assert torch.equal(noisy.quat[40:], state.quat[40:])  # rotation off: untouched
    assert torch.equal(noisy.angvel[40:], state.angvel[40:])


def test_push_forward_rolls_the_model_and_targets_the_true_frame():
    from physgnn.data.state import TrajectoryFrames
    from physgnn.physics.integrator import step
    from physgnn.training.lit import push_forward

    lit = make_lit(dict(engine_state=False))  # the engine state's: tests/test_engine_state.py
    frames = TrajectoryFrames(trajectory(3, frames=8, seed=5))
    state = Batch.from_data_list([frames.state(3, 2, future=2)])
    out = push_forward(state, lit.simulator, 2)
    expected = state.clone()
    for _ in range(2):  # the same two steps by hand
        v, w = lit.simulator(expected)
        expected.pos, expected.quat, expected.vel, expected.angvel = step(
            expected.pos,
            expected.quat,
            expected.vel,
            expected.angvel,
            v,
            w,
            state.scene_dt,
            lit.simulator.rotating(expected),
        )
    assert_close(out.pos, expected.pos)
    assert_close(out.vel, expected.vel)
    assert_close(out.target_vel, (frames.pos[6] - out.pos) / 0.1, rtol=1e-4, atol=1e-4)
    assert_close(out.target_angvel, frames.angvel[6])
    zero = push_forward(state, lit.simulator, 0)  # no step: the one-step target
    assert_close(zero.target_vel, (frames.pos[4] - frames.pos[3]) / 0.1, rtol=1e-4, atol=1e-4)


def pairs(n_traj: int = 2) -> list:
    from physgnn.data.state import TrajectoryFrames

    frames = [TrajectoryFrames(trajectory(3, seed=s)) for s in range(n_traj)]
    return [f.state(t, 1) for f in frames for t in range(1, 10)]


class Poison(Callback):
    """Sets a weight to NaN when epoch 1 starts."""

    def on_train_epoch_start(self, trainer, pl_module):
        if trainer.current_epoch == 1:
            with torch.no_grad():
                next(pl_module.simulator.parameters()).fill_(float("nan"))


def test_non_finite_loss_stops_with_one_line_and_keeps_checkpoint(tmp_path):
    lit = make_lit()
    ckpt = ModelCheckpoint(dirpath=tmp_path, save_last=True)
    trainer = L.Trainer(
        max_epochs=3,
        callbacks=[ckpt, Poison()],
        logger=False,
        enable_progress_bar=False,
        enable_model_summary=False,
    )
    data = DataLoader(pairs(), batch_size=6)
    with pytest.raises(NonFiniteLossError) as info:
        trainer.fit(lit, data)
    message = str(info.value)
    assert "\n" not in message and "non-finite training loss (nan) at epoch 1" in message
    saved = torch.load(tmp_path / "last.ckpt", weights_only=True)
    assert saved["epoch"] == 0
    assert all(
        torch.isfinite(v).all() for v in saved["state_dict"].values() if v.is_floating_point()
    )


def test_scheduler_is_stepped_per_epoch():
    sched = functools.partial(torch.optim.lr_scheduler.ExponentialLR, gamma=0.5)
    lit = make_lit(scheduler=sched)
    conf = lit.configure_optimizers()
    assert conf["lr_scheduler"]["interval"] == "epoch"
    assert isinstance(conf["optimizer"], torch.optim.Adam)


def test_negative_hyperparameters_rejected():
    with pytest.raises(ConfigError, match=r"^lit.noise.std must be a number >= 0 .*got -1.0"):
        InputNoise(std=-1.0)
    with pytest.raises(ConfigError, match=r"^lit.pushforward.after must be a whole number >= 0"):
        PushForward(after=-1)


def test_noise_is_reproducible_from_a_seeded_generator():
    lit = make_lit()
    state = batch([trajectory(5, seed=8)])
    draw = [
        add_noise(state, lit.simulator, 0.1, torch.Generator().manual_seed(s)) for s in (1, 1, 2)
    ]
    assert torch.equal(draw[0].pos, draw[1].pos) and torch.equal(draw[0].vel, draw[1].vel)
    assert not torch.equal(draw[0].pos, draw[2].pos)


def test_compile_keeps_the_weights_and_checkpoint_keys():
    """``Compile(enabled=True)`` compiles in place (lazily, on the first call) the graph rules, the
    simulator's step after the graph build and the losses after theirs, or with graphs padded
    to buckets the network alone: same parameters, same state_dict keys, so checkpoints load
    either way."""
    eager, compiled = make_lit(), make_lit(compile=Compile(enabled=True))
    sim = compiled.simulator
    assert isinstance(sim.head, ShapeBoundCall) and isinstance(
        compiled.graph_losses, ShapeBoundCall
    )
    assert isinstance(sim.graph_builder.rules, ShapeBoundCall)
    assert not isinstance(eager.simulator.head, ShapeBoundCall)
    padded = make_lit({"pad_to_buckets": True}, compile=Compile(enabled=True))
    assert isinstance(padded.simulator.network.forward, ShapeBoundCall)
    assert not isinstance(padded.simulator.head, ShapeBoundCall)
    assert list(compiled.state_dict()) == list(eager.state_dict())
    for a, b in zip(eager.state_dict().values(), compiled.state_dict().values(), strict=True):
        assert torch.equal(a, b)


@pytest.mark.slow
def test_compiled_regions_give_the_eager_losses_and_gradients():
    state = batch([trajectory(3, seed=0), trajectory(4, seed=1)])
    results = []
    for lit in (make_lit(), make_lit(compile=Compile(enabled=True))):
        loss = lit.losses(state)["loss"]
        loss.backward()
        # parameters of an interaction the batch lacks (no pp edge) get no gradient
        grads = [None if p.grad is None else p.grad.clone() for p in lit.parameters()]
        results.append((loss.detach(), grads))
    (loss_e, grads_e), (loss_c, grads_c) = results
    assert_close(loss_c, loss_e, rtol=1e-5, atol=1e-6)
    assert [g is None for g in grads_c] == [g is None for g in grads_e]
    assert any(g is not None for g in grads_e)
    for g_c, g_e in zip(grads_c, grads_e, strict=True):
        if g_e is not None:
            assert_close(g_c, g_e, rtol=1e-4, atol=1e-6)


class AtStep(LitSimulator):
    """A LitSimulator whose global step is set by hand (no trainer)."""

    at = 0

    @property
    def global_step(self) -> int:
        return self.at


def test_push_forward_growth_lengthens_the_unroll_step_by_step():
    sim = learned(H=1, M=1, hidden=8)
    lit = AtStep(sim, ADAM, pushforward=PushForward(steps=3, after=10, growth=5))
    highs = {}
    for step in (9, 10, 14, 15, 20, 40):
        lit.at = step
        draws = set()
        for seed in range(200):
            lit.seed = seed
            draws.add(lit._unroll_length())
        highs[step] = max(draws)
    assert highs == {9: 0, 10: 1, 14: 1, 15: 2, 20: 3, 40: 3}


class AtRank(AtStep):
    """... and its DDP process."""

    rank = 0

    @property
    def global_rank(self) -> int:
        return self.rank


def test_each_ddp_process_draws_its_own_noise_and_all_the_same_unroll():
    lit = AtRank(learned(H=1, M=1, hidden=8), ADAM, seed=3, pushforward=PushForward(after=0))
    draws = {}
    for lit.at in range(20):
        for lit.rank in range(3):
            noise = torch.rand(4, generator=lit._noise_generator())
            draws[lit.at, lit.rank] = (noise, lit._unroll_length())
    # process 0 draws what one process always drew: seeded by seed · 1 000 003 + step
    alone = torch.Generator().manual_seed(3 * 1_000_003 + 7)
    assert torch.equal(draws[7, 0][0], torch.rand(4, generator=alone))
    assert len({tuple(noise.tolist()) for noise, _ in draws.values()}) == 60  # all differ
    assert all(draws[k, r][1] == draws[k, 0][1] for k, r in draws)
    assert {draws[k, 0][1] for k in range(20)} == {0, 1, 2}
    lit.at, lit.rank = 7, 1  # reproducible for (seed, process, step)
    assert torch.equal(torch.rand(4, generator=lit._noise_generator()), draws[7, 1][0])
    # the CPU generator takes a seed's low 32 bits: those of any two of 1 024 processes lie
    # 1.9 million steps apart or more (noise.RANK_STRIDE)
    low = [(noise_seed(0, 0, d) % 2**32) for d in range(1, 1024)]
    assert min(min(x, 2**32 - x) for x in low) > 1_900_000


def test_contact_settings_out_of_range_are_refused():
    with pytest.raises(ConfigError, match=r"^lit.loss.lambda_contact must be a number >= 0"):
        LossTerms(lambda_contact=-1.0)
    prob = r"^lit.noise.contact_prob must be a number in \[0, 1\] \(a probability.*\(the default: "
    with pytest.raises(ConfigError, match=prob + r"lit.noise.contact_prob=0.3\)$"):
        InputNoise(contact_prob=1.5)
    with pytest.raises(
        ConfigError, match=r"^lit.noise.rest_scale must be a number in \(0, 1\] \(a factor"
    ):
        InputNoise(rest_scale=float("nan"))
    with pytest.raises(ConfigError, match=r"^lit.compile.mode must be one of default, "):
        Compile(mode="fastest")


def test_losses_with_the_contact_terms_are_finite_and_the_penalty_counts():
    state = batch([trajectory(3, seed=0), trajectory(2, seed=1)])
    lit = make_lit(REPORT_MODEL, loss=LossTerms(lambda_contact=2.0))
    losses = lit.losses(state)
    expected = losses["loss_mse"] + 2.0 * losses["loss_contact"]
    assert_close(losses["loss"], expected)
    assert torch.isfinite(losses["loss"]) and float(losses["loss_mse"].detach()) > 0
    assert float(losses["loss_rest"].detach()) == 0.0  # no rest decision


def resting_pair_and_a_faller():
    """A touching pair at rest on the ground (target: rest) and a sphere at the top of its
    flight 3 m up (target: v + g dt), with materials; dt 0.1 s."""
    state = scene([[0, 0, 0.5], [1.0, 0, 0.5], [5, 0, 3]], [[0, 0, 0]] * 3, [0.5] * 3)
    state.vel[2, 1:] = torch.tensor([0.0, 0.0, 0.981])  # ballistic history: out of reach
    state.target_vel = torch.tensor([[0.0, 0, 0], [0, 0, 0], [0, 0, -0.981]])
    state.target_angvel = torch.zeros(3, 3)
    return state


def test_default_losses_add_the_rest_term_over_the_spheres_in_reach():
    state = resting_pair_and_a_faller()
    lit = make_lit(loss=LossTerms(lambda_contact=2.0, lambda_rest=0.5))
    sim = lit.simulator
    losses = lit.losses(state)
    expected = losses["loss_mse"] + 2.0 * losses["loss_contact"] + 0.5 * losses["loss_rest"]
    assert_close(losses["loss"], expected)
    assert float(losses["loss_mse"].detach()) > 0 and float(losses["loss_rest"].detach()) > 0
    pred, graph = sim.normalized_prediction(state)
    reach = sim.in_reach(state, graph)
    assert reach.tolist() == [True, True, False]
    assert sim.rest_target(state).tolist() == [True, True, False]
    # binary cross-entropy of the rest logit against "at rest", over the spheres in reach
    logit = sim.outputs.take(pred, "rest")[:2, 0]
    expected_rest = torch.nn.functional.softplus(-logit).mean()
    assert_close(rest_loss(sim, state, pred, reach), expected_rest)
    assert_close(losses["loss_rest"], expected_rest)


def test_rest_loss_is_zero_without_a_rest_decision():
    state = resting_pair_and_a_faller()
    sim = make_lit(dict(rest_decision=False)).simulator
    pred, graph = sim.normalized_prediction(state)
    assert pred.shape == (3, 12)  # Δv, Δω of the end velocities and of the mean motion
    assert float(rest_loss(sim, state, pred, sim.in_reach(state, graph)).detach()) == 0.0
    losses = make_lit(dict(rest_decision=False)).losses(state)
    assert float(losses["loss_rest"].detach()) == 0.0 and float(losses["loss_mse"].detach()) > 0


def test_regime_scale_gives_resting_spheres_the_rest_scale_and_fast_ones_one():
    sim = make_lit().simulator
    sigma = float(sim.speed_scale)
    assert sigma == pytest.approx(7.0**0.5)  # RMS of the velocity std (1, 2, 4)
    # at rest; fast; 1 m/s; spinning at 2 rad/s with r 0.5 (1 m/s at the surface)
    state = scene(
        [[0, 0, 0.5], [3, 0, 3], [6, 0, 3], [9, 0, 3]],
        [[0, 0, 0], [10, 0, 0], [0, 0.6, -0.8], [0, 0, 0]],
        [0.5] * 4,
    )
    state.angvel[3, 0] = torch.tensor([0.0, 2.0, 0.0])
    scale = regime_scale(state, sim, 0.05)
    assert scale.shape == (4, 1, 1)
    expected = torch.tensor([0.05, 1.0, 1.0 / sigma, 1.0 / sigma])
    assert_close(scale.flatten(), expected)
    assert_close(regime_scale(state, sim, 1.0).flatten(), torch.ones(4))


def test_regime_scaled_noise_is_the_uniform_noise_times_the_scale():
    sim = make_lit().simulator
    state = scene([[0, 0, 0.5], [3, 0, 3]], [[0, 0, 0], [10, 0, 0]], [0.5] * 2)
    state.target_vel = state.vel[:, 0].clone()
    uniform = add_noise(state, sim, 0.1, torch.Generator().manual_seed(4))
    scaled = add_noise(state, sim, 0.1, torch.Generator().manual_seed(4), rest_scale=0.05)
    factor = torch.tensor([0.05, 1.0])[:, None, None]
    assert_close(scaled.vel - state.vel, factor * (uniform.vel - state.vel))
    assert_close(scaled.angvel - state.angvel, factor * (uniform.angvel - state.angvel))
    assert_close(scaled.pos - state.pos, factor[:, 0] * (uniform.pos - state.pos))
    assert float((uniform.vel - state.vel)[0].abs().max()) > 0
