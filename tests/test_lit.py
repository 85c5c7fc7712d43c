"""LitSimulator: energy term by hand, masked MSE, noise only in training, non-finite loss."""

from __future__ import annotations

import functools

import lightning as L
import pytest
import torch
from lightning.pytorch.callbacks import Callback, ModelCheckpoint
from simdata import STATS, batch, trajectory
from torch.testing import assert_close
from torch_geometric.data import Batch
from torch_geometric.loader import DataLoader

from physgnn.data.state import SceneState
from physgnn.models.learned import LearnedSimulator
from physgnn.physics.scene import Effects
from physgnn.training.lit import (
    LitSimulator,
    NonFiniteLossError,
    add_noise,
    energy_increase,
    masked_mse,
)

ADAM = functools.partial(torch.optim.Adam, lr=1e-3)


def make_lit(**kwargs) -> LitSimulator:
    torch.manual_seed(0)
    return LitSimulator(LearnedSimulator(STATS, H=1, M=1, hidden=8), ADAM, **kwargs)


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
    state = batch([trajectory(3, seed=2)])
    plain, weighted = make_lit(lambda_energy=0.0), make_lit(lambda_energy=0.5)
    a, b = plain.losses(state), weighted.losses(state)
    assert_close(a["loss"], a["loss_mse"])
    assert_close(b["loss"], b["loss_mse"] + 0.5 * b["loss_energy"])
    assert_close(a["loss_energy"], b["loss_energy"])
    assert_close(a["energy_share"], torch.tensor(0.0))
    assert_close(b["energy_share"], 0.5 * b["loss_energy"] / b["loss"])


def test_noise_only_in_training_shaped_like_a_rollout_with_correcting_targets():
    lit = make_lit(noise_std=0.1)
    still = trajectory(40, seed=4, effects=Effects(rotation=False))
    state = batch([trajectory(40, seed=3), still])
    seen = []
    original = lit.simulator.normalized_prediction
    lit.simulator.normalized_prediction = lambda s: seen.append(s) or original(s)
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

    lit = make_lit()
    frames = TrajectoryFrames(trajectory(3, frames=8, seed=5))
    state = Batch.from_data_list([frames.state(3, 2, future=2)])
    out = push_forward(state, lit.simulator, 2)
    expected = state.clone()
    for _ in range(2):  # the same two steps by hand
        v, w = lit.simulator(expected)
        expected.pos, expected.quat, expected.vel, expected.angvel = step(
            expected.pos, expected.quat, expected.vel, expected.angvel, v, w,
            state.scene_dt, lit.simulator.rotating(expected),
        )  # fmt: skip
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
    with pytest.raises(ValueError, match="must be >= 0"):
        make_lit(noise_std=-1.0)


def test_noise_is_reproducible_from_a_seeded_generator():
    lit = make_lit()
    state = batch([trajectory(5, seed=8)])
    draw = [
        add_noise(state, lit.simulator, 0.1, torch.Generator().manual_seed(s)) for s in (1, 1, 2)
    ]
    assert torch.equal(draw[0].pos, draw[1].pos) and torch.equal(draw[0].vel, draw[1].vel)
    assert not torch.equal(draw[0].pos, draw[2].pos)


def test_compile_keeps_the_weights_and_checkpoint_keys():
    """``compile=True`` compiles the network in place (lazily, on its first call): same
    parameters, same state_dict keys, so checkpoints load either way."""
    eager, compiled = make_lit(), make_lit(compile=True)
    assert compiled.simulator.network._compiled_call_impl is not None
    assert eager.simulator.network._compiled_call_impl is None
    assert list(compiled.state_dict()) == list(eager.state_dict())
    for a, b in zip(eager.state_dict().values(), compiled.state_dict().values(), strict=True):
        assert torch.equal(a, b)


@pytest.mark.slow
def test_compiled_network_gives_the_eager_losses_and_gradients():
    state = batch([trajectory(3, seed=0), trajectory(4, seed=1)])
    results = []
    for lit in (make_lit(), make_lit(compile=True)):
        loss = lit.losses(state)["loss"]
        loss.backward()
        grads = [p.grad.clone() for p in lit.parameters()]
        results.append((loss.detach(), grads))
    (loss_e, grads_e), (loss_c, grads_c) = results
    assert_close(loss_c, loss_e, rtol=1e-5, atol=1e-6)
    for g_c, g_e in zip(grads_c, grads_e, strict=True):
        assert_close(g_c, g_e, rtol=1e-4, atol=1e-6)


class AtStep(LitSimulator):
    """A LitSimulator whose global step is set by hand (no trainer)."""

    at = 0

    @property
    def global_step(self) -> int:
        return self.at


def test_push_forward_growth_lengthens_the_unroll_step_by_step():
    sim = LearnedSimulator(STATS, H=1, M=1, hidden=8)
    lit = AtStep(sim, ADAM, pushforward_steps=3, pushforward_after=10, pushforward_growth=5)
    highs = {}
    for step in (9, 10, 14, 15, 20, 40):
        lit.at = step
        draws = set()
        for seed in range(200):
            lit.seed = seed
            draws.add(lit._unroll_length())
        highs[step] = max(draws)
    assert highs == {9: 0, 10: 1, 14: 1, 15: 2, 20: 3, 40: 3}


def test_contact_settings_out_of_range_are_refused():
    with pytest.raises(ValueError, match="lit.lambda_contact"):
        make_lit(lambda_contact=-1.0)
    with pytest.raises(ValueError, match="contact_noise_prob"):
        make_lit(contact_noise_prob=1.5)


def test_losses_with_the_contact_terms_are_finite_and_the_penalty_counts():
    state = batch([trajectory(3, seed=0), trajectory(2, seed=1)])
    lit = make_lit(lambda_contact=2.0)
    losses = lit.losses(state)
    expected = losses["loss_mse"] + 2.0 * losses["loss_contact"]
    assert_close(losses["loss"], expected)
    assert torch.isfinite(losses["loss"])
