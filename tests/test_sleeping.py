"""Sleeping spheres (physgnn.models.sleeping): falling asleep, islands, waking, exactness."""

import numpy as np
import pytest
import torch
from torch_geometric.data import Batch

from physgnn.data.state import SceneState, TrajectoryFrames, subset_state
from physgnn.graph.builder import GraphBuilder
from physgnn.models.sleeping import SleepingSimulator
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import Effects, Material, ground_plane
from physgnn.physics.trajectory import Trajectory


class Billiard:
    """Hand-made oracle: spheres on the ground keep their velocity; two equal spheres about to
    overlap swap velocities (a head-on elastic hit). Records the spheres it was called on."""

    H = 0

    def __init__(self):
        self.graph_builder = GraphBuilder("vi", epsilon=0.01)
        self.calls: list[int] = []

    def __call__(self, state):
        self.calls.append(state.pos.shape[0])
        vel = state.vel[:, 0].clone()
        graph = self.graph_builder(state)
        half = graph.num_pairs
        j, i = graph.pp_index[:, :half]
        nxt = state.pos + vel * state.scene_dt[:, None]
        hit = (nxt[i] - nxt[j]).norm(dim=-1) < state.radius[i] + state.radius[j]
        i, j = i[hit], j[hit]
        vel[i], vel[j] = state.vel[j, 0], state.vel[i, 0]
        return vel, state.angvel[:, 0].clone()

    def rotating(self, state):
        return state.effects[:, 4][state.batch] if state.batch is not None else state.effects[:, 4]


def _scene_state(pos, vel, radius=0.5, angvel=None):
    """One scene at one frame (H = 0) from ``pos, vel [N, 3]`` lists; ground only."""
    pos = torch.tensor(pos, dtype=torch.float32)
    n = pos.shape[0]
    vel = torch.tensor(vel, dtype=torch.float32)
    ang = torch.zeros(n, 3) if angvel is None else torch.tensor(angvel, dtype=torch.float32)
    return SceneState(
        pos=pos,
        quat=Q.identity(n),
        vel=vel[:, None],
        angvel=ang[:, None],
        radius=torch.full((n,), radius),
        mass=torch.ones(n),
        material=torch.zeros(n, dtype=torch.long),
        planes=torch.as_tensor(ground_plane())[None],
        plane_kind=torch.zeros(1, dtype=torch.long),
        plane_batch=torch.zeros(1, dtype=torch.long),
        dt=torch.tensor([0.1]),
        effects=torch.ones(1, 5, dtype=torch.bool),
    )


def _roll(sim, state, steps):
    """Minimal rollout (H = 0): positions ``[steps + 1, N, 3]``, quats, asleep flags."""
    pos, quat, asleep = [state.pos], [state.quat], []
    for _ in range(steps):
        vel, angvel = sim(state)
        p, q = state.pos + state.scene_dt[:, None] * vel, Q.integrate(state.quat, angvel, 0.1)
        if isinstance(sim, SleepingSimulator):
            p, q = sim.hold(state.pos, state.quat, p, q)
            asleep.append(sim.asleep.clone())
        state = state.clone()
        state.pos, state.quat, state.vel, state.angvel = p, q, vel[:, None], angvel[:, None]
        pos.append(p)
        quat.append(q)
    return torch.stack(pos), torch.stack(quat), asleep


def test_resting_sphere_sleeps_then_wakes_when_hit_and_matches_no_sleeping():
    # Sphere 0 rests at x = 0; sphere 1 rolls in from x = -3 at 2 m/s (gap 2 m, 0.2 m/frame).
    state = _scene_state([[0, 0, 0.5], [-3, 0, 0.5]], [[0, 0, 0], [2, 0, 0]])
    plain = Billiard()
    pos_ref, quat_ref, _ = _roll(plain, state, 25)
    inner = Billiard()
    sim = SleepingSimulator(inner, threshold=0.05, k=3)
    pos, quat, asleep = _roll(sim, state, 25)
    flags = torch.stack(asleep).int()
    # 0 is still from the start: asleep at call k = 3 (index 2). 1 reaches the wake distance
    # (gap 2 − 0.2·s ≤ |v|·dt + ε = 0.21) at s = 9 and hits it then; 0 leaves at 2 m/s, 1 stops
    # and, still for 3 frames, falls asleep at index 12.
    assert flags[:, 0].tolist() == [0, 0] + [1] * 7 + [0] * 16
    assert flags[:, 1].tolist() == [0] * 12 + [1] * 13
    assert inner.calls == [2, 2] + [1] * 7 + [2] * 3 + [1] * 13  # sleepers left out
    assert torch.equal(pos, pos_ref) and torch.equal(quat, quat_ref)
    assert float(pos[-1, 0, 0]) == pytest.approx(3.2) and float(pos[-1, 1, 0]) == pytest.approx(
        -1.2
    )
    assert sim.wakes == 1 and sim.sleep_frames == 7 + 13


def test_nothing_asleep_is_bit_identical_and_calls_with_the_same_state():
    state = _scene_state([[0, 0, 0.5], [3, 0, 0.5]], [[0.01, 0, 0], [1, 0, 0]])
    seen = []

    class Spy(Billiard):
        def __call__(self, s):
            seen.append(s)
            return super().__call__(s)

    sim = SleepingSimulator(Spy(), threshold=0.05, k=100)
    v, w = sim(state)
    assert seen[0] is state  # not a copy: exactly what the no-sleeping rollout computes
    v_ref, w_ref = Billiard()(state)
    assert torch.equal(v, v_ref) and torch.equal(w, w_ref)


def test_touching_a_moving_sphere_keeps_the_whole_chain_awake():
    # 0–1–2 touch in a row; 2 spins fast in place (r·|ω| = 5 m/s); 3 rests alone far away.
    state = _scene_state(
        [[0, 0, 0.5], [1, 0, 0.5], [2, 0, 0.5], [10, 0, 0.5]],
        [[0, 0, 0]] * 4,
        angvel=[[0, 0, 0], [0, 0, 0], [0, 0, 10], [0, 0, 0]],
    )

    class Frozen(Billiard):  # a simulator that keeps the state as it is
        def __call__(self, s):
            return s.vel[:, 0].clone(), s.angvel[:, 0].clone()

    sim = SleepingSimulator(Frozen(), threshold=0.05, k=2)
    for _ in range(4):
        sim(state)
    assert sim.asleep.tolist() == [False, False, False, True]
    assert sim.still.tolist() == [4, 4, 0, 2]  # the sleeper stopped counting when it fell asleep
    # Once 2 stops spinning, the whole row falls asleep together (after k still frames).
    state.angvel.zero_()
    sim(state)
    assert sim.asleep.tolist() == [False, False, False, True]
    sim(state)
    assert sim.asleep.tolist() == [True, True, True, True]


def test_a_still_sphere_within_reach_of_a_moving_one_stays_awake():
    # 1 is 0.3 m from 0 and comes at 5 m/s (reach 0.5 + ε); 2 rests 2 m away from everything.
    state = _scene_state(
        [[0, 0, 0.5], [-1.3, 0, 0.5], [0, 3, 0.5]], [[0, 0, 0], [5, 0, 0], [0] * 3]
    )

    class Frozen(Billiard):
        def __call__(self, s):
            return s.vel[:, 0].clone(), s.angvel[:, 0].clone()

    sim = SleepingSimulator(Frozen(), threshold=0.05, k=1)
    sim(state)
    assert sim.asleep.tolist() == [False, False, True]


def test_waking_one_sphere_wakes_its_whole_island():
    # A resting row 0–1–2 (touching) and a far sphere 3; all asleep. Then 4 arrives near 0 only.
    state = _scene_state(
        [[0, 0, 0.5], [1, 0, 0.5], [2, 0, 0.5], [9, 0, 0.5], [-1.15, 0, 0.5]],
        [[0, 0, 0]] * 4 + [[1.0, 0, 0]],
    )
    sim = SleepingSimulator(Billiard(), threshold=0.05, k=1)
    sim.asleep = torch.tensor([True, True, True, True, False])
    sim.still = torch.tensor([5, 5, 5, 5, 0])
    vel, _ = sim(state)
    # gap 0.15 ≤ |v|·dt + ε = 0.11? No: 0 is out of reach; nothing wakes yet.
    assert sim.asleep.tolist() == [True, True, True, True, False]
    assert torch.equal(vel[:4], torch.zeros(4, 3)) and float(vel[4, 0]) == 1.0
    state.pos[4, 0] = -1.05  # gap 0.05 ≤ 0.11: sphere 0 wakes, and 1, 2 with it; 3 sleeps on
    sim(state)
    assert sim.asleep.tolist() == [False, False, False, True, False]
    assert sim.wakes == 3 and sim.still.tolist()[:3] == [0, 0, 0]


def test_the_seed_history_counts_so_spheres_resting_from_the_start_sleep_at_once():
    state = _scene_state([[0, 0, 0.5], [3, 0, 5], [6, 0, 0.5], [9, 0, 0.5]], [[0] * 3] * 4)
    # Histories, latest first: at rest; dropped from rest at frame 0 (v = 0, 0.98, 1.96 m/s
    # down); stopped 2 frames ago; spinning in place (r·|ω| = 0.5 m/s).
    state.vel = torch.zeros(4, 3, 3)
    state.vel[1, :, 2] = torch.tensor([-1.962, -0.981, 0.0])
    state.vel[2, 2, 0] = 1.0
    state.angvel = torch.zeros(4, 3, 3)
    state.angvel[3, :, 2] = 1.0
    sim = SleepingSimulator(Billiard(), threshold=0.05, k=3)
    sim(state)
    assert sim.still.tolist() == [3, 0, 2, 0]
    assert sim.asleep.tolist() == [True, False, False, False]


@pytest.mark.parametrize("connectivity, wakes", [("vi", False), ("vmax", True), ("epsilon", False)])
def test_wake_distance_is_the_graph_rule_of_the_simulator(connectivity, wakes):
    # Sleeper 0; sphere 1 at gap 0.15 m coming at 1 m/s: vi links gap ≤ 0.1 + ε, vmax
    # gap ≤ 2 · 0.1 + ε, epsilon gap ≤ ε (ε = 0.01).
    state = _scene_state([[0, 0, 0.5], [-1.15, 0, 0.5]], [[0, 0, 0], [1.0, 0, 0]])
    inner = Billiard()
    inner.graph_builder = GraphBuilder(connectivity, epsilon=0.01)
    sim = SleepingSimulator(inner)
    sim.asleep, sim.still = torch.tensor([True, False]), torch.tensor([5, 0])
    sim(state)
    assert sim.asleep.tolist() == [not wakes, False]
    graph = inner.graph_builder(state)
    assert (graph.num_pairs == 1) == wakes  # exactly when the graph links them


def test_hold_keeps_position_and_orientation_exactly():
    sim = SleepingSimulator(Billiard())
    sim.asleep = torch.tensor([True, False])
    pos, quat = torch.randn(2, 3), Q.normalize(torch.randn(2, 4))
    p2, q2 = sim.hold(pos, quat, pos + 1, quat * 2)
    assert torch.equal(p2[0], pos[0]) and torch.equal(q2[0], quat[0])
    assert torch.equal(p2[1], pos[1] + 1) and torch.equal(q2[1], quat[1] * 2)


def _traj(n, seed):
    rng = np.random.default_rng(seed)
    t = 3
    pos = np.repeat(rng.uniform(-5, 5, (1, n, 3)), t, 0).astype(np.float32)
    return Trajectory(
        name=f"t{seed}",
        pos=pos,
        quat=np.tile(np.array([1, 0, 0, 0], np.float32), (t, n, 1)),
        vel=np.zeros((t, n, 3), np.float32),
        angvel=np.zeros((t, n, 3), np.float32),
        radius=np.full(n, 0.5, np.float32),
        mass=np.arange(1, n + 1, dtype=np.float32),
        material=np.zeros(n, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=Material().as_array()[None],
        dt=0.1,
        effects=Effects(),
    )


def test_subset_state_keeps_scenes_planes_and_recomputes_ptr():
    batch = Batch.from_data_list([TrajectoryFrames(_traj(n, n)).state(1, 1) for n in (2, 3)])
    mask = torch.tensor([False, False, True, False, True])
    sub = subset_state(batch, mask)
    assert torch.equal(sub.mass, torch.tensor([1.0, 3.0]))
    assert torch.equal(sub.batch, torch.tensor([1, 1]))
    assert torch.equal(sub.ptr, torch.tensor([0, 0, 2]))
    assert sub.vel.shape == (2, 2, 3) and sub.num_graphs == 2
    assert torch.equal(sub.planes, batch.planes) and torch.equal(sub.dt, batch.dt)
    assert batch.pos.shape == (5, 3)  # the original is untouched


@pytest.mark.parametrize(
    "kwargs, match",
    [({"threshold": -1}, "threshold"), ({"k": 0}, "k must"), ({"touch": float("nan")}, "touch")],
)
def test_bad_settings_get_one_clear_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SleepingSimulator(Billiard(), **kwargs)


# ----- through physgnn.rollout -----------------------------------------------------------
def _line_trajectory(frames: int = 30) -> Trajectory:
    """Sphere 0 rests at x = 0; sphere 1 rolls in from x = −3 at 2 m/s (frames: the truth
    of the Billiard oracle, used only for the first frame)."""
    t = np.arange(frames)[:, None] * 0.1
    pos = np.zeros((frames, 2, 3), np.float32)
    pos[:, :, 2] = 0.5
    pos[:, 1, 0] = (-3 + 2 * t[:, 0]).astype(np.float32)
    vel = np.zeros((frames, 2, 3), np.float32)
    vel[:, 1, 0] = 2.0
    quat = np.tile(np.array([1, 0, 0, 0], np.float32), (frames, 2, 1))
    return Trajectory(
        name="line",
        pos=pos,
        quat=quat,
        vel=vel,
        angvel=np.zeros_like(vel),
        radius=np.full(2, 0.5, np.float32),
        mass=np.ones(2, np.float32),
        material=np.zeros(2, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=Material().as_array()[None],
        dt=0.1,
    )


def test_rollout_with_sleeping_holds_sleepers_exactly_and_wakes_them_when_hit():
    from physgnn.rollout import rollout

    traj = _line_trajectory()
    (plain,) = rollout(Billiard(), [traj], history=0)
    inner = Billiard()
    (slept,) = rollout(inner, [traj], history=0, sleep={"k": 3})
    assert np.array_equal(slept.pos, plain.pos) and np.array_equal(slept.quat, plain.quat)
    assert 1 in inner.calls and inner.calls[-1] == 1  # 0 slept, then 1 after its hit
    assert float(slept.pos[-1, 0, 0]) > 3.0  # the sleeper was hit and rolled away


def test_rollout_where_nobody_sleeps_is_bit_identical_to_no_sleeping():
    from simdata import learned, trajectory

    from physgnn.rollout import rollout

    torch.manual_seed(0)
    sim = learned(H=1, M=2, hidden=16).eval()
    sim.effects_trained.fill_(True)
    trajs = [trajectory(4, frames=12, seed=s) for s in range(2)]
    ref = rollout(sim, trajs)
    for sleep in ({"threshold": 0.0}, {"threshold": 1e9, "k": 100}):
        out = rollout(sim, trajs, sleep=sleep)
        for a, b in zip(ref, out, strict=True):
            assert np.array_equal(a.pos, b.pos) and np.array_equal(a.quat, b.quat)
            assert np.array_equal(a.vel, b.vel) and a.n_frames == b.n_frames == 12
    # With a huge threshold and k = 1 everything sleeps at once and then stays exactly put.
    (frozen,) = rollout(sim, trajs[:1], sleep={"threshold": 1e9, "k": 1})
    assert np.array_equal(frozen.pos[2:], np.broadcast_to(frozen.pos[2], frozen.pos[2:].shape))
    assert np.array_equal(frozen.quat[2:], np.broadcast_to(frozen.quat[2], frozen.quat[2:].shape))
    assert np.array_equal(frozen.vel[2:], np.zeros_like(frozen.vel[2:]))


# ----- physgnn.sleep_study ---------------------------------------------------------------------
def test_drift_before_hit_stops_counting_when_the_truth_moves():
    from physgnn.metrics import drift_before_hit

    true = np.zeros((6, 3, 3))
    true[4:, 1, 0] = 1.0  # sphere 1 is hit at frame 4
    true[1:, 2, 2] = -np.arange(1, 6)  # sphere 2 falls from the start: not a resting one
    pred = np.zeros((6, 3, 3))
    pred[:, 0, 1] = [0, 0, 0.1, 0.2, 0.3, 0.4]  # sphere 0 drifts 0.4 m
    pred[:, 1, 1] = [0, 0, 0.5, 0.6, 2.0, 9.0]  # sphere 1 drifts 0.6 m before its hit
    pred[:, 2, 0] = 100.0 * np.arange(6)  # whatever the falling sphere does is not rest drift
    radius = np.array([0.5, 0.5, 0.5])
    assert drift_before_hit(pred, true, radius, start=1) == pytest.approx([0.8, 1.2])
    true[1:, :, 2] = 1.0  # everything moves during the seed frames: nothing rests
    assert drift_before_hit(pred, true, radius, start=1).shape == (0,)


def test_frozen_share_counts_unchanged_sphere_steps():
    from physgnn.evaluation.sleep_study import frozen_share

    pos = np.zeros((5, 2, 3))
    pos[:, 1, 0] = np.arange(5)  # sphere 1 moves, sphere 0 never does
    assert frozen_share(pos, start=1) == pytest.approx(50.0)
    assert frozen_share(pos[:2], start=1) == 0.0


def test_sleep_state_survives_a_scene_leaving_the_batch():
    from physgnn.rollout import rollout

    long, short = _line_trajectory(30), _line_trajectory(8)
    inner = Billiard()
    ref = rollout(Billiard(), [long, short], history=0)
    out = rollout(inner, [long, short], history=0, sleep={"k": 3})
    for a, b in zip(ref, out, strict=True):
        assert np.array_equal(a.pos, b.pos) and a.n_frames == b.n_frames
    # Calls see 4 spheres, then 2 (both resting spheres asleep, k = 3) until the short scene
    # leaves after 7 steps; then the long scene's rolling sphere alone: its sleeper stays
    # asleep (without `select` its sleep state would be lost and it would be back, awake).
    assert inner.calls[:7] == [4, 4, 2, 2, 2, 2, 2]
    assert inner.calls[7:9] == [1, 1]


@pytest.mark.parametrize("name, key", [("eval", "rollout.sleep"), ("sleep_study", "sleep")])
def test_configs_are_off_by_default_and_agree_with_the_class_defaults(name, key):
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from physgnn import CONF_DIR

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(name)
    if name == "eval":
        assert cfg.rollout.sleeping is False  # off until measured (README: sleeping spheres)
    settings = OmegaConf.to_container(OmegaConf.select(cfg, key))
    sim, default = SleepingSimulator(Billiard(), **settings), SleepingSimulator(Billiard())
    assert (sim.threshold, sim.k, sim.touch) == (default.threshold, default.k, default.touch)


def test_sleep_study_compare_rows_and_missing_run_error():
    from omegaconf import OmegaConf

    from physgnn.evaluation.sleep_study import COLUMNS, compare, study

    traj = _line_trajectory(20)

    class Oracle(Billiard):
        H = 0
        timings: dict = {}

    off, on = compare(Oracle(), traj, {"k": 3})
    assert set(off) == set(COLUMNS) and (off["sleeping"], on["sleeping"]) == ("off", "on")
    assert off["mse"] == on["mse"] and off["rest_drift"] == on["rest_drift"]
    # The "truth" of this trajectory never moves sphere 0; the oracle's hit sends it 2 m away.
    assert on["rest_drift"] == pytest.approx(2.0 / 0.5, rel=1e-5)
    # The oracle keeps resting spheres exactly still anyway: the same frames are frozen.
    assert off["frozen_pct"] == on["frozen_pct"] == pytest.approx(100 * 19 / 38)
    with pytest.raises(ValueError, match="pass run=PATH"):
        study(OmegaConf.create({"run": None}))


def test_learned_rollout_with_a_whole_scene_asleep_in_the_batch():
    from simdata import learned, trajectory
    from torch.testing import assert_close

    from physgnn.rollout import rollout

    torch.manual_seed(0)
    sim = learned(H=1, M=2, hidden=16).eval()
    sim.effects_trained.fill_(True)
    resting = _traj(4, seed=3)  # 3 frames at rest
    resting.pos[..., 2] = 0.5  # on the ground
    moving = trajectory(3, frames=10, seed=1)
    rest, move = rollout(sim, [resting, moving], n_frames=10, sleep={"k": 2})
    (alone,) = rollout(sim, [moving], n_frames=10)
    # The resting scene sleeps from the first step (2 still seed frames) and never moves.
    assert np.array_equal(rest.pos, np.broadcast_to(resting.pos[0], rest.pos.shape))
    assert np.array_equal(rest.quat, np.broadcast_to(resting.quat[0], rest.quat.shape))
    # The moving scene ran in a batch whose other scene had no sphere left: same result.
    assert_close(torch.as_tensor(move.pos), torch.as_tensor(alone.pos))
