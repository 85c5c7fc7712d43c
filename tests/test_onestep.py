"""The one-step error by regime: the truth's regimes on hand-built motions, a simulator that
answers the truth, pybullet at the truth's own substeps, and onestep.csv and its section in
``make eval`` on the tiny preset."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
import torch
from fakeruns import Falling, eval_cfg, make_run
from omegaconf import OmegaConf
from truthkit import spheres

import physgnn.training.runs
from physgnn.data.dataset import read_split
from physgnn.errors import ConfigError
from physgnn.evaluation import evaluate as ev
from physgnn.evaluation import onestep
from physgnn.evaluation.runs import RunInfo
from physgnn.groundtruth.engine import one_frame_from, simulate
from physgnn.metrics.regimes import ALL, REGIMES, regime_rows, tally
from physgnn.models.options import ModelInputs
from physgnn.physics.kinematics import finite_difference_velocities
from physgnn.physics.trajectory import Trajectory
from physgnn.report import onestep as onestep_report

G, DT, R = 9.81, 0.1, 0.5


def motion(z0, vz0, frames, e=0.8, x0=0.0, vx=0.0):
    """One ball under gravity bouncing on the ground (restitution ``e``) at the instant it
    touches it: positions and end-of-frame velocities ``[T, 3]``, exact."""
    pos, vel = [(x0, 0.0, z0)], [(vx, 0.0, vz0)]
    z, v = z0, vz0
    for t in range(1, frames):
        left = DT
        s = (v + np.sqrt(v * v + 2 * G * (z - R))) / G  # when z next reaches R
        if s <= DT:
            v, z, left = -e * (v - G * s), R, DT - s
        z, v = z + v * left - G * left * left / 2, v - G * left
        pos.append((x0 + vx * t * DT, 0.0, z))
        vel.append((vx, 0.0, v))
    return np.array(pos), np.array(vel)


def trajectory(pos, vel) -> Trajectory:
    """pos, vel ``[T, N, 3]`` over the ground, the engine's velocities given."""
    return Trajectory.from_arrays(
        pos, R, DT, velocities=(vel, np.zeros_like(vel)), name=("hand", {"engine": "hand"})
    )


def names(labels) -> list[str]:
    return [REGIMES[k] for k in labels]


def test_a_ball_in_flight_is_flight_in_every_frame():
    pos, vel = motion(50.0, 3.0, 8)
    labels = onestep.truth_labels(trajectory(pos[:, None], vel[:, None]))
    assert names(labels[:, 0]) == ["flight"] * 7


def test_a_bounce_is_a_plane_impact_then_flight_after_a_contact():
    pos, vel = motion(2.0, 0.0, 9)  # touches the ground at 0.553 s: in frame 5 -> 6
    labels = names(onestep.truth_labels(trajectory(pos[:, None], vel[:, None]))[:, 0])
    assert labels == ["flight"] * 5 + ["plane_impact", "flight_after_contact", "flight"]


def test_a_ball_resting_or_rolling_on_the_ground():
    rest = np.tile([0.0, 0.0, R], (6, 1))
    rolling = rest + np.arange(6)[:, None] * np.array([DT * 1.0, 0.0, 0.0])
    pos = np.stack([rest, rolling + [5.0, 0.0, 0.0]], axis=1)
    vel = np.zeros_like(pos)
    vel[:, 1, 0] = 1.0
    labels = onestep.truth_labels(trajectory(pos, vel))
    assert names(labels[:, 0]) == ["rest"] * 5 and names(labels[:, 1]) == ["rolling"] * 5


def test_two_balls_colliding_in_the_air():
    """Head-on at ±2 m/s, 1 m apart: they touch at 0.25 s (frame 2 -> 3) and swap velocities;
    the ground is 10 m below."""
    t = np.arange(7) * DT
    z = 10.0 - G * t**2 / 2
    hit = 0.25
    x = np.where(t < hit, -1.0 + 2.0 * t, -1.0 + 2.0 * hit - 2.0 * (t - hit))
    pos = np.stack([np.stack([x, 0 * t, z], -1), np.stack([-x, 0 * t, z], -1)], axis=1)  # [T, 2, 3]
    vx = np.where(t < hit, 2.0, -2.0)
    vel = np.stack([np.stack([vx, 0 * t, -G * t], -1), np.stack([-vx, 0 * t, -G * t], -1)], 1)
    labels = onestep.truth_labels(trajectory(pos, vel))
    expected = ["flight", "flight", "sphere", "flight_after_contact", "flight", "flight"]
    assert names(labels[:, 0]) == names(labels[:, 1]) == expected


def test_rows_share_frames_and_error_and_sum_to_all():
    labels = np.array([[0, 1], [1, 2]])
    err = np.array([[1.0, 3.0], [5.0, 0.0]])
    rows = {r["regime"]: r for r in regime_rows(*tally(labels, err))}
    assert rows["flight_after_contact"] == {
        "regime": "flight_after_contact",
        "sphere_frames": 2,
        "share_frames": 0.5,
        "mse": 4.0,
        "share_error": 8 / 9,
    }
    assert rows["rest"]["mse"] == 0.0 and rows["sphere"]["mse"] is None
    assert rows[ALL]["sphere_frames"] == 4 and rows[ALL]["mse"] == 9 / 4


class Oracle(torch.nn.Module):
    """Answers the truth of the frame it is shown, found by its positions; checks that the
    state's velocities are the ones its kind of state carries."""

    H = 2

    def __init__(self, traj: Trajectory, engine_state: bool):
        super().__init__()
        self.inputs = ModelInputs(engine_state=engine_state)
        self.pos = torch.as_tensor(traj.pos)
        first = torch.as_tensor(traj.vel[0]), torch.as_tensor(traj.angvel[0])
        quat = torch.as_tensor(traj.quat)
        self.mean, self.mean_w = finite_difference_velocities(self.pos, quat, *first, traj.dt)
        self.end, self.end_w = torch.as_tensor(traj.vel), torch.as_tensor(traj.angvel)

    def forward(self, state):
        assert getattr(state, "target_vel", None) is None  # the answer is not shown
        n = self.pos.shape[1]
        pos = state.pos.reshape(-1, n, 3)
        ts = [int((self.pos == p).all(-1).all(-1).nonzero()[0]) for p in pos]
        seen = self.end if self.inputs.engine_state else self.mean
        assert torch.equal(state.vel[:, 0], seen[ts].reshape(-1, 3))
        assert state.vel.shape[1] == self.H + 1
        nxt = [t + 1 for t in ts]
        answer = [self.end[nxt], self.end_w[nxt], self.mean[nxt], self.mean_w[nxt]]
        answer = [a.reshape(-1, 3) for a in answer]
        return tuple(answer) if self.inputs.engine_state else tuple(answer[2:])


@pytest.mark.parametrize("engine_state", [False, True])
def test_a_simulator_answering_the_truth_has_no_error_in_any_regime(engine_state):
    bounce, vb = motion(2.0, 0.0, 30, x0=-3.0)
    fly, vf = motion(40.0, 1.0, 30, x0=3.0)
    traj = trajectory(np.stack([bounce, fly], 1), np.stack([vb, vf], 1))
    predict = partial(onestep.learned_positions, Oracle(traj, engine_state))
    truth = [(traj, onestep.truth_labels(traj))]
    rows = onestep.table_rows("oracle", "test", truth, 2, None, predict)
    by = {r["regime"]: r for r in rows}
    assert by[ALL]["sphere_frames"] == 2 * 27
    assert by["plane_impact"]["sphere_frames"] > 0 and by["flight_after_contact"]["sphere_frames"]
    for row in rows:
        assert row["mse"] is None or row["mse"] < 1e-10, row


def test_pybullet_at_the_truths_own_substeps_reproduces_it():
    """Two balls meeting above the ground and one dropped on it, at 5 substeps."""
    scene = spheres(
        [[-1.0, 0.0, 1.2], [0.2, 0.0, 1.2], [3.0, 0.0, 1.5]],
        vel=[[3.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.5, 0.0, 0.0]],
        n_frames=25,
    )
    traj = simulate(scene, {"substeps": 5})
    labels = onestep.truth_labels(traj)
    assert {"sphere", "plane_impact", "flight_after_contact"} <= set(names(labels.ravel()))
    ts = onestep.onestep_frames(traj, 1)
    pred = onestep.engine_positions(traj, ts, 5)
    assert np.abs(pred - traj.pos[ts + 1]).max() < 1e-5
    coarse = onestep.engine_positions(traj, ts, 1)
    assert np.abs(coarse - traj.pos[ts + 1]).max() > 1e-3


def test_a_restart_wakes_a_body_that_fell_asleep_at_rest():
    """30 starts at rest on the ground (3 s: Bullet puts a body to sleep after 2 s), then one
    thrown up at 5 m/s: it leaves the ground as a fresh engine's would."""
    scene = spheres([[0.0, 0.0, R]], n_frames=2)
    rest = (scene.pos, scene.quat, np.zeros((1, 3)), np.zeros((1, 3)))
    thrown = (scene.pos, scene.quat, np.array([[0.0, 0.0, 5.0]]), np.zeros((1, 3)))
    pos = one_frame_from(scene, [rest] * 30 + [thrown], {"substeps": 40})
    assert np.abs(pos[:30, 0, 2] - R).max() < 1e-3
    assert pos[30, 0, 2] == pytest.approx(R + 5.0 * DT - G * DT * DT * 41 / 80, abs=1e-4)


def test_frames_evenly_spaced_and_settings_checked():
    traj = trajectory(*[a[:, None] for a in motion(50.0, 0.0, 12)])
    assert onestep.onestep_frames(traj, 2).tolist() == list(range(2, 11))
    assert onestep.onestep_frames(traj, 2, 3).tolist() == [2, 6, 10]
    assert onestep.check_settings(None) is None
    ok = OmegaConf.create({"splits": ["test", "ood"], "frames": None})
    assert onestep.check_settings(ok) == (["test", "ood"], None)
    for bad in ({"splits": ["val"], "frames": None}, {"splits": ["test"], "frames": 0}):
        with pytest.raises(ConfigError, match="onestep"):
            onestep.check_settings(OmegaConf.create(bad))


def test_make_eval_writes_onestep_csv_and_its_section(tiny_dataset, tmp_path, monkeypatch):
    """A run that falls freely, on the tiny preset: its rows and pybullet's at 1 and 40
    substeps (the truth's own: no error), on test and OOD, 10 frames per trajectory."""
    outputs = tmp_path / "outputs"
    make_run(outputs / "runs" / "baseline" / "t0")
    cfg = OmegaConf.create({"datamodule": {"data_dir": str(tiny_dataset)}})
    monkeypatch.setattr(physgnn.training.runs, "load_run", lambda run_dir: (Falling(), cfg, {}))
    overrides = [
        f"paths.outputs={outputs}",
        "videos=false",
        "pybullet.substeps=[1,40]",
        "pybullet.processes=1",
        "onestep.splits=[test,ood]",
        "onestep.frames=10",
    ]
    text = ev.evaluate(eval_cfg(*overrides)).read_text()
    rows = onestep_report.read_csv(outputs / "report" / "onestep.csv")
    runs = ["runs/baseline/t0", "pybullet-1", "pybullet-40"]
    assert list(dict.fromkeys(r["run"] for r in rows)) == runs
    assert len(rows) == 2 * len(runs) * (len(REGIMES) + 1)
    ood = read_split(tiny_dataset / "ood.h5")
    for split in ("test", "ood"):
        mine = [r for r in rows if r["split"] == split]
        total = next(r for r in mine if r["run"] == "pybullet-40" and r["regime"] == ALL)
        assert total["mse"] < 1e-8
        if split == "ood":
            assert total["sphere_frames"] == sum(10 * t.n_spheres for t in ood)
        shares = [r["share_frames"] for r in mine if r["run"] == runs[0] and r["regime"] != ALL]
        assert sum(shares) == pytest.approx(1.0)
    assert "## One-step error by regime" in text and "| flight after a contact |" in text
    assert "`pybullet-40`: MSE (share)" in text
    text = ev.evaluate(eval_cfg(*overrides, "onestep=null", "overwrite=true")).read_text()
    assert "No one-step table" in text


def test_report_section_of_rows():
    rows = [
        {"run": "a", "split": "test", **r}
        for r in regime_rows(*tally(np.array([0, 1]), np.array([0.0, 2.0])))
    ]
    text = onestep_report.section(rows)
    assert "| flight after a contact | 1 | 50.0 % | 2 (100.0 %) |" in text
    assert "No one-step table" in onestep_report.section([])


def test_runs_without_a_learned_simulator_have_no_rows():
    ref = RunInfo(name="static", experiment="reference")
    assert onestep.onestep_rows([ref], {}, (["test"], None), [1], False) == []
