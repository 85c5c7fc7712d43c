"""Rollout engine (physgnn.rollout) against hand-computed integrations."""

import math

import numpy as np
import pytest
import torch
from torch import nn

from physgnn import metrics as M
from physgnn.data.state import TrajectoryFrames
from physgnn.models.profiling import StepTimer
from physgnn.physics.scene import Effects, ground_plane
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import RolloutBounds, RolloutError, rollout

DT = 0.1


def linear_traj(p0, v0, frames=12, name="lin", effects=None, radius=0.5):
    """Spheres moving at constant velocity ``v0 [N, 3]`` from ``p0 [N, 3]``, identity quats."""
    p0, v0 = np.asarray(p0, np.float64), np.asarray(v0, np.float64)
    n = len(p0)
    pos = p0 + v0 * DT * np.arange(frames)[:, None, None]
    quat = np.zeros((frames, n, 4), np.float32)
    quat[..., 0] = 1
    return Trajectory(
        name=name,
        pos=pos.astype(np.float32),
        quat=quat,
        vel=np.broadcast_to(v0, (frames, n, 3)).astype(np.float32),
        angvel=np.zeros((frames, n, 3), np.float32),
        radius=np.full(n, radius, np.float32),
        mass=np.ones(n, np.float32),
        material=np.zeros(n, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=np.zeros((1, 4), np.float32),
        dt=DT,
        effects=effects or Effects(),
    )


class Constant(nn.Module):
    """Predicts the same v and ω for every sphere; records the velocity histories it sees."""

    def __init__(self, v, w, H=1):
        super().__init__()
        self.v, self.w, self.H, self.seen = torch.tensor(v), torch.tensor(w), H, []

    def forward(self, state):
        self.seen.append(state.vel.clone())
        n = state.pos.shape[0]
        return self.v.expand(n, 3).clone(), self.w.expand(n, 3).clone()


class Exploding(nn.Module):
    """``v̂ = factor · v_t``: grows geometrically, so its divergence step is known."""

    H = 0

    def __init__(self, factor=10.0):
        super().__init__()
        self.factor = factor

    def forward(self, state):
        return self.factor * state.vel[:, 0], state.angvel[:, 0]


class Replay(nn.Module):
    """Returns the true next velocities of one trajectory (the rollout replays the truth)."""

    def __init__(self, traj, H):
        super().__init__()
        self.frames, self.H, self.t = TrajectoryFrames(traj), H, H

    def forward(self, state):
        self.t += 1
        return self.frames.vel[self.t], self.frames.angvel[self.t]


def test_constant_velocity_rollout_matches_the_integrator_by_hand():
    traj = linear_traj([[0, 0, 5], [3, 0, 5]], [[0, 0, 0], [0, 0, 0]], frames=8)
    sim = Constant([1.0, -2.0, 0.5], [0.0, 0.0, 2.0], H=1)
    (res,) = rollout(sim, [traj])
    assert res.n_frames == 8 and res.diverged_at is None and res.start == 1
    k = np.arange(8)[:, None, None] - 1.0  # steps after the start frame H = 1
    expect = traj.pos[1] + np.clip(k, 0, None) * DT * np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(res.pos, expect, atol=1e-5)
    np.testing.assert_allclose(res.vel[2:], np.broadcast_to([1.0, -2.0, 0.5], (6, 2, 3)), atol=2e-5)
    # q ← normalise(q + ½·dt·(0, ω)⊗q) about z: the half angle grows by atan(½·dt·ω) a step.
    half = np.clip(k[:, :, 0], 0, None) * math.atan(0.5 * DT * 2.0)
    quat = np.stack([np.cos(half), 0 * half, 0 * half, np.sin(half)], -1)
    np.testing.assert_allclose(res.quat, np.broadcast_to(quat, (8, 2, 4)), atol=1e-6)
    # Histories are shifted: the second call sees [v̂, v_H] (latest first).
    assert len(sim.seen) == 6
    torch.testing.assert_close(sim.seen[1][:, 0], torch.tensor([[1.0, -2.0, 0.5]] * 2))
    torch.testing.assert_close(sim.seen[1][:, 1], torch.zeros(2, 3))


def test_rotation_off_leaves_orientation_untouched():
    traj = linear_traj([[0, 0, 5]], [[0, 0, 0]], frames=5, effects=Effects(rotation=False))
    traj.quat[:] = np.array([0.5, 0.5, 0.5, 0.5], np.float32)
    (res,) = rollout(Constant([0.0, 0, 0], [3.0, 1.0, 0.0], H=0), [traj])
    assert np.array_equal(res.quat, traj.quat)


def test_exploding_simulator_stops_at_the_step_computed_by_hand():
    # Speed 1 m/s at the start, ×10 per step: 1e5 > 1e4 at the 5th step, frame H + 5 = 5.
    boom = linear_traj([[0, 0, 5]], [[1.0, 0, 0]], frames=20, name="boom")
    rest = linear_traj([[0, 0, 0.5]], [[0.0, 0, 0]], frames=20, name="rest")
    res_boom, res_rest = rollout(Exploding(), [boom, rest])
    assert res_boom.diverged_at == 5 and res_boom.n_frames == 5 and res_boom.pos.shape[0] == 5
    assert np.isfinite(res_boom.pos).all()
    assert res_rest.diverged_at is None and res_rest.n_frames == 20  # the other scene goes on
    np.testing.assert_allclose(res_boom.pos[:, 0, 0], [0, 1, 11, 111, 1111], rtol=1e-6)
    out = M.trajectory_metrics(res_boom, boom)
    assert out["diverged_at"] == 5 and out["n_frames"] == 5 and np.isfinite(out["mse"])
    # The bound relative to the truth: 10 × max(1 m/s, 1) = 10 m/s, exceeded by 100 m/s.
    (res,) = rollout(Exploding(), [boom], bounds=RolloutBounds(speed_factor=10.0))
    assert res.diverged_at == 2


def test_non_finite_prediction_stops_the_scene():
    class NanAt3(Exploding):
        calls = 0

        def forward(self, state):
            self.calls += 1
            v = state.vel[:, 0] + (float("nan") if self.calls == 3 else 0.0)
            return v, state.angvel[:, 0]

    (res,) = rollout(NanAt3(), [linear_traj([[0, 0, 5]], [[1.0, 0, 0]])])
    assert res.diverged_at == 3 and res.pos.shape == (3, 1, 3) and np.isfinite(res.vel).all()


def test_replayed_truth_has_the_metrics_of_the_truth():
    rng = np.random.default_rng(3)
    frames, n = 30, 6
    t = np.arange(frames)[:, None, None] * DT
    pos = rng.uniform(0, 2, (1, n, 3)) + [0, 0, 1] + rng.normal(0, 1, (1, n, 3)) * t
    pos[..., 2] = np.abs(pos[..., 2] - 4.9 * t[..., 0] ** 2)  # fall, reflect at the ground
    traj = linear_traj(pos[0], np.zeros((n, 3)), frames=frames)
    traj.pos = pos.astype(np.float32)
    H = 2
    (res,) = rollout(Replay(traj, H), [traj])
    direct = M.trajectory_metrics(traj.with_finite_velocities(), traj)
    through = M.trajectory_metrics(res, traj)
    assert direct["pct_sphere"] > 0 and direct["pct_ground"] > 0 and direct["energy_gain"] > 0
    assert through["mse"] < 1e-10 and through["rotation_error"] == 0.0
    for key in ("energy_gain", *M.PENETRATION_KEYS):
        assert through[key] == pytest.approx(direct[key], rel=1e-4, abs=1e-6), key


def test_batched_scenes_of_different_lengths_and_longer_than_the_truth():
    a = linear_traj([[0, 0, 5]], [[1.0, 0, 0]], frames=6, name="a")
    b = linear_traj([[0, 0, 5], [4, 0, 5]], [[0, 1.0, 0], [0, 1.0, 0]], frames=9, name="b")
    ra, rb = rollout(Constant([0.0, 0, 1.0], [0.0, 0, 0], H=0), [a, b])
    assert ra.pos.shape == (6, 1, 3) and rb.pos.shape == (9, 2, 3)
    np.testing.assert_allclose(rb.pos[-1, :, 2], 5 + 8 * DT, rtol=1e-6)
    (long,) = rollout(Constant([0.0, 0, 0], [0.0, 0, 0], H=0), [a], n_frames=15)
    assert long.n_frames == 15
    one_by_one = rollout(Constant([0.0, 0, 1.0], [0.0, 0, 0], H=0), [a, b], batch_size=1)
    np.testing.assert_allclose(one_by_one[1].pos, rb.pos)


def test_timings_split_graph_network_integration():
    timer = StepTimer()

    class Timed(Constant):
        def forward(self, state):
            timer.graph += 0.25  # graph seconds, as a watched graph builder adds them
            return super().forward(state)

    sim = Timed([0.0, 0, 0], [0.0, 0, 0], H=0)
    (res,) = rollout(sim, [linear_traj([[0, 0, 5]], [[0.0, 0, 0]], frames=5)], timer=timer)
    assert timer.timings["steps"] == 4 and timer.timings["graph"] == pytest.approx(1.0)
    assert timer.timings["network"] < 0  # the fake graph seconds exceed the real call time
    assert res.fps == pytest.approx(4 / timer.timings["total"])


def test_bad_input_is_one_clear_error():
    short = linear_traj([[0, 0, 5]], [[0.0, 0, 0]], frames=2)
    with pytest.raises(RolloutError, match="H\\+1 = 3 frames"):
        rollout(Constant([0.0, 0, 0], [0.0, 0, 0], H=2), [short])
    nan = linear_traj([[0, 0, 5]], [[0.0, 0, 0]], frames=4)
    nan.pos[0, 0, 0] = np.nan
    with pytest.raises(RolloutError, match="NaN"):
        rollout(Constant([0.0, 0, 0], [0.0, 0, 0], H=0), [nan])
    with pytest.raises(RolloutError, match="history=H"):
        rollout(lambda s: (s.pos, s.pos), [short])
    with pytest.raises(RolloutError, match="sleep must be True, False or a dict"):
        rollout(Constant([0.0, 0, 0], [0.0, 0, 0], H=0), [short], sleep="yes")


def test_sleeping_freezes_resting_spheres_and_keeps_the_result():
    # Sphere 0 rests on the ground, sphere 1 flies away at 1 m/s: still at 2 calls (k = 2),
    # sphere 0 sleeps and the simulator sees only sphere 1; positions are unchanged.
    traj = linear_traj([[0, 0, 0.5], [5, 0, 5]], [[0, 0, 0], [1.0, 0, 0]], frames=10)

    class Keep(Constant):
        def forward(self, state):
            self.seen.append(state.vel.clone())
            return state.vel[:, 0].clone(), torch.zeros_like(state.pos)

    plain, sleepy = Keep([0.0] * 3, [0.0] * 3, H=0), Keep([0.0] * 3, [0.0] * 3, H=0)
    (ref,) = rollout(plain, [traj])
    (res,) = rollout(sleepy, [traj], sleep=dict(threshold=0.01, k=2))
    np.testing.assert_array_equal(res.pos, ref.pos)
    assert [v.shape[0] for v in plain.seen] == [2] * 9
    assert [v.shape[0] for v in sleepy.seen] == [2] + [1] * 8  # still at calls 1 and 2
    # sleep=True: the SleepingSimulator's own settings (k = 3: sphere 0 sleeps after 3 calls).
    default = Keep([0.0] * 3, [0.0] * 3, H=0)
    (on,) = rollout(default, [traj], sleep=True)
    np.testing.assert_array_equal(on.pos, ref.pos)
    assert [v.shape[0] for v in default.seen] == [2, 2] + [1] * 7


def test_unseen_effect_warns_once_and_seen_effects_are_silent():
    import warnings

    sim = Constant([0.0] * 3, [0.0] * 3, H=0)
    sim.effects_trained = torch.tensor([True, True, True, True, False])  # never rotated
    trajs = [linear_traj([[0, 0, 5]], [[0.0, 0, 0]], frames=3, name=f"s{i}") for i in range(3)]
    with pytest.warns(UserWarning, match=r"\['rotation'\].*never saw") as record:
        rollout(sim, trajs, batch_size=1)
    assert len(record) == 1
    still = [linear_traj([[0, 0, 5]], [[0.0, 0, 0]], frames=3, effects=Effects(rotation=False))]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rollout(sim, still)


def test_no_frame_reaches_the_host_before_the_rollout_ends(monkeypatch):
    """The device path (graph building by the torch backend, as on a GPU): the number of
    ``.cpu()`` / ``.numpy()`` calls of a rollout does not grow with its frames."""
    from simdata import learned, trajectory

    torch.manual_seed(0)
    sim = learned(H=1, M=1, hidden=8, neighbor_backend="torch").eval()
    sim.effects_trained.fill_(True)
    traj = trajectory(4, frames=30, seed=3)
    calls = {"cpu": 0, "numpy": 0}
    for name in calls:
        original = getattr(torch.Tensor, name)

        def counted(self, *args, _name=name, _original=original, **kwargs):
            calls[_name] += 1
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(torch.Tensor, name, counted)
    counts = []
    for frames in (6, 26):
        calls.update(cpu=0, numpy=0)
        (out,) = rollout(sim, [traj], n_frames=frames, device="cpu")
        assert out.n_frames == frames and out.diverged_at is None
        counts.append(dict(calls))
    assert counts[0] == counts[1], counts


def test_evaluation_batches_a_split_and_equals_one_by_one_up_to_rounding():
    """``make eval``'s default: a split's scenes in one rollout call give the one-by-one
    rollouts up to float rounding, the same frames, and fps as scene-frames per second."""
    from simdata import learned, trajectory

    from physgnn.evaluation.rollouts import predict, predict_split
    from physgnn.evaluation.runs import RunInfo

    torch.manual_seed(0)
    sim = learned(H=1, M=1, hidden=8, neighbor_backend="torch").eval()
    sim.effects_trained.fill_(True)
    job = RunInfo("run", "baseline", simulator=sim)
    trajs = [trajectory(n, frames=15, seed=n) for n in (2, 3, 5)]
    batched = predict_split(job, trajs)
    again = predict_split(job, trajs)
    for traj, pred, repeat in zip(trajs, batched, again, strict=True):
        alone = predict(job, traj)
        assert pred.n_frames == alone.n_frames == traj.n_frames
        assert pred.diverged_at is None and alone.diverged_at is None
        np.testing.assert_allclose(pred.pos, alone.pos, rtol=0, atol=1e-4)
        np.testing.assert_array_equal(pred.pos, repeat.pos)  # deterministic
    # every scene produced 15 - 2 frames in the call's time: fps counts all three scenes'
    fps = [p.fps for p in batched]
    assert fps[0] == fps[1] == fps[2] and math.isfinite(fps[0]) and fps[0] > 0
    truth = RunInfo("ground_truth", "reference")
    for traj, pred in zip(trajs, predict_split(truth, trajs), strict=True):
        np.testing.assert_array_equal(pred.pos, traj.pos)


def test_batched_fps_counts_the_frames_every_scene_produced(monkeypatch):
    """Two scenes from frame 1: one ran 10 steps, one diverged after 4; the call made 10 steps
    at 5 steps/s (2 s), so its scene-frames per second are (10 + 4) / 2 = 7."""
    import dataclasses

    from simdata import trajectory

    from physgnn.evaluation import rollouts
    from physgnn.evaluation.runs import RunInfo

    long, short = trajectory(2, frames=12, seed=1), trajectory(2, frames=6, seed=2)
    made = [dataclasses.replace(t, start=1, fps=5.0) for t in (long, short)]
    monkeypatch.setattr(rollouts, "rollout", lambda sim, trajs, **kw: made)
    preds = rollouts.predict_split(RunInfo("run", "x", simulator=object()), [long, short])
    assert [p.fps for p in preds] == [7.0, 7.0]


def test_rollout_settings_turn_the_eval_keys_into_the_sleep_argument():
    from omegaconf import OmegaConf

    from physgnn.evaluation.rollouts import rollout_settings, sleep_settings

    def cfg(sleeping, sleep):
        return OmegaConf.create({"rollout": {"sleeping": sleeping, "sleep": sleep}})

    assert rollout_settings(cfg(False, {"k": 3})) == {"sleep": False}
    assert rollout_settings(cfg(True, {"k": 3})) == {"sleep": {"k": 3}}
    assert rollout_settings(cfg(True, None)) == {"sleep": {}}  # the SleepingSimulator defaults
    assert sleep_settings(cfg(False, {"k": 3})) == {"k": 3}
