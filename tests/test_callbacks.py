"""RolloutCallback: what it logs, when, and with which values (static simulator as oracle)."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch
from simdata import trajectory

from physgnn.errors import ConfigError
from physgnn.evaluation.rollouts import metrics_row
from physgnn.rollout import rollout
from physgnn.training.callbacks import RolloutCallback


class Still(torch.nn.Module):
    """Predicts v = ω = 0: the rollout holds frame H for ever."""

    H = 1

    def forward(self, state):
        return torch.zeros_like(state.pos), torch.zeros_like(state.pos)


class FakeModule:
    def __init__(self):
        self.simulator = Still()
        self.logged = {}

    def log(self, name, value, **kwargs):
        self.logged[name] = value


def held_mse(traj, h=1, frames=None) -> float:
    """Position MSE of a rollout that holds frame h: frames ≤ h exact, then p_h (over the first
    ``frames`` frames; None: all)."""
    pos = traj.pos[:frames].astype(np.float64)
    pred = pos.copy()
    pred[h:] = pos[h]
    return float(((pred - pos) ** 2).sum(-1).mean())


def callback_with(val, ood_trajs, **kwargs):
    """The callback (horizon 5 unless given: the trajectories here are short) with ``val`` and
    ``ood_trajs`` as its splits."""
    cb = RolloutCallback(**({"horizon": 5} | kwargs))
    cb._cache = {"val": val, "ood": ood_trajs}  # what _trajectories would have read and cut
    return cb


def test_logs_every_key_with_the_oracle_mse():
    val = [trajectory(3, 10, seed=1), trajectory(2, 10, seed=2)]
    ood = [trajectory(4, 10, seed=3)]
    module = FakeModule()
    values = callback_with(val, ood, ood=True).log_rollouts(module, data_dir=None)
    assert set(module.logged) == {
        "val/mse5",
        "val/rollout_mse",
        "val/energy_gain",
        "val/rollout_score",
        "val/max_depth",
        "val/tunnelled",
        "val/rest_drift",
        "val/chamfer",
        "ood/mse",
        "ood/chamfer",
        "ood/energy_gain",
        "ood/depth_sphere",
        "ood/pct_sphere",
        "ood/diverged",
        "rollout/fps",
    }
    assert module.logged == values
    # the validation rollouts stop at frame H + horizon = 6: their MSE is over frames 0..6
    window = [held_mse(t, frames=7) for t in val]
    assert values["val/rollout_mse"] == pytest.approx(np.mean(window))
    at_horizon = [float(((t.pos[6] - t.pos[1]) ** 2).sum(-1).mean()) for t in val]
    assert values["val/mse5"] == pytest.approx(np.mean(at_horizon))
    diameter = np.mean(np.concatenate([2 * t.radius for t in val]))
    physics = 10 * values["val/max_depth"] + 10 * values["val/tunnelled"]
    physics += values["val/rest_drift"]
    expected = values["val/mse5"] / diameter**2 + physics  # nothing diverged
    assert values["val/rollout_score"] == pytest.approx(expected)
    assert values["ood/mse"] == pytest.approx(held_mse(ood[0]))  # OOD: whole rollouts
    assert values["ood/diverged"] == 0.0 and values["rollout/fps"] > 0


def test_ood_off_logs_validation_only():
    module = FakeModule()
    callback_with([trajectory(2, 8)], [trajectory(2, 8)], ood=False).log_rollouts(module, None)
    assert set(module.logged) == {
        "val/mse5",
        "val/rollout_mse",
        "val/rollout_score",
        "val/chamfer",
        "val/energy_gain",
        "rollout/fps",
        "val/max_depth",
        "val/tunnelled",
        "val/rest_drift",
    }


def test_runs_every_n_epochs_and_skips_sanity_check():
    cb = callback_with([trajectory(2, 8)], [], every_n_epochs=2)
    module = FakeModule()
    trainer = SimpleNamespace(
        sanity_checking=True, current_epoch=0, datamodule=SimpleNamespace(data_dir="unused")
    )
    cb.on_validation_epoch_end(trainer, module)
    assert module.logged == {}
    trainer.sanity_checking = False
    cb.on_validation_epoch_end(trainer, module)  # no score yet: rolls out at once
    assert "val/rollout_mse" in module.logged
    first = module.logged["val/rollout_score"]
    module.logged.clear()
    trainer.current_epoch = 2  # not due: the latest score is logged again, no rollout
    cb.on_validation_epoch_end(trainer, module)
    assert module.logged == {"val/rollout_score": first}
    trainer.current_epoch = 3  # due
    cb.on_validation_epoch_end(trainer, module)
    assert "val/rollout_mse" in module.logged
    assert cb.state_dict() == {"score": module.logged["val/rollout_score"]}


def test_a_diverged_validation_rollout_scores_infinity():
    class Exploding(torch.nn.Module):
        H = 2

        def forward(self, state):
            return state.vel[:, 0] * 1e6, state.angvel[:, 0]

    module = FakeModule()
    module.simulator = Exploding()
    callback_with([trajectory(2, 10)], [], ood=False).log_rollouts(module, None)
    assert module.logged["val/rollout_score"] == float("inf")
    assert "val/mse5" not in module.logged  # no rollout reached the horizon


class Slowing(torch.nn.Module):
    """Keeps 90 % of the latest velocity: a rollout that drifts off the truth."""

    H = 2

    def forward(self, state):
        return 0.9 * state.vel[:, 0], state.angvel[:, 0]


def test_the_logged_mse20_is_the_evals_mse20_of_the_same_rollouts():
    val = [trajectory(3, 40, seed=1), trajectory(5, 30, seed=2)]
    module = FakeModule()
    module.simulator = Slowing()
    cb = RolloutCallback(ood=False)  # the default horizon, 20: the eval's MSE20
    cb._cache = {"val": val}
    values = cb.log_rollouts(module, data_dir=None)
    # the eval's rows, each trajectory rolled out whole and alone
    run = SimpleNamespace(name="run", experiment="e", overrides="", seed=0)
    evals = [metrics_row(run, "val", t, rollout(Slowing(), [t])[0], tol=0.0) for t in val]
    torch.testing.assert_close(values["val/mse20"], float(np.mean([r["mse20"] for r in evals])))
    diameter = np.mean(np.concatenate([2 * t.radius for t in val]))
    physics = 10 * values["val/max_depth"] + 10 * values["val/tunnelled"]
    physics += values["val/rest_drift"]
    assert values["val/rollout_score"] == pytest.approx(values["val/mse20"] / diameter**2 + physics)


def test_a_validation_trajectory_too_short_for_the_horizon_is_refused():
    cb = callback_with([trajectory(2, 10), trajectory(2, 30)], [], horizon=20)
    with pytest.raises(ConfigError, match=r"has 10 frames, the score needs H \+ horizon \+ 1 = 22"):
        cb.log_rollouts(FakeModule(), data_dir=None)


def row(mse=2.0, sphere=0.0, ground=0.0, static=0.0, tunnelled=0, rest=None, diverged=None):
    """A rollout's row: ``mse`` its MSE20 (None once it diverged), its whole MSE far off."""
    out = dict(max_pen_sphere=sphere, max_pen_ground=ground, max_pen_static=static, mse=1e3)
    out |= dict(tunnelled=tunnelled, n_spheres=4, rest_drift=rest, diverged_at=diverged)
    return out | {"mse20": None if diverged is not None else mse}


def test_the_score_adds_depth_tunnelling_and_rest_drift_to_the_mse20():
    cb = RolloutCallback(w_depth=10.0, w_tunnel=10.0, w_rest=1.0)
    assert cb.score_terms([row()], 2.0)["val/rollout_score"] == pytest.approx(0.5)  # 2 / 2²
    soft = cb.score_terms([row(sphere=0.5, ground=0.1, static=0.3)], 2.0)
    assert soft["val/max_depth"] == pytest.approx(0.8)  # sphere + the deeper plane
    assert soft["val/rollout_score"] == pytest.approx(0.5 + 8.0)
    through = cb.score_terms([row(tunnelled=1, rest=3.0), row()], 2.0)
    assert through["val/tunnelled"] == pytest.approx(0.125)  # (1/4 + 0) / 2
    assert through["val/rest_drift"] == pytest.approx(1.5)
    assert through["val/rollout_score"] == pytest.approx(0.5 + 1.25 + 1.5)
    assert cb.score_terms([row(), row(diverged=3)], 2.0)["val/rollout_score"] == float("inf")


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="every_n_epochs"):
        RolloutCallback(every_n_epochs=0)
    with pytest.raises(ValueError, match="horizon"):
        RolloutCallback(horizon=0)
