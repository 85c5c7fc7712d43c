"""Bounce evaluation: the apex after the first bounce, against e² and pybullet."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physgnn.evaluation.bounce import _first_apex, bounce_rows
from physgnn.physics.energy import G
from physgnn.physics.trajectory import Trajectory
from physgnn.report import bounce


class Reflecting(torch.nn.Module):
    """Free flight, and at a frame that would end below the ground the vertical velocity
    reversed and scaled by the sphere's restitution (from its material row)."""

    H = 2

    def forward(self, state):
        dt = state.scene_dt
        vel = state.vel[:, 0].clone()
        vel[:, 2] -= G * dt
        below = state.pos[:, 2] + dt * vel[:, 2] < state.radius
        e = state.material_params[:, 0]
        vel[:, 2] = torch.where(below, -e * state.vel[:, 0, 2], vel[:, 2])
        return vel, state.angvel[:, 0]


def test_first_apex_is_the_flight_invariant_after_the_bounce():
    dt, u, r = 0.1, 6.0, 0.5
    z = [3.0, 2.0, 1.0]  # falling
    vz = [-10.0, -10.0, -10.0]
    v = u
    for _ in range(12):  # semi-implicit Euler up from z = 1
        v -= G * dt
        z.append(z[-1] + dt * v)
        vz.append(v)
    vz[3] = u - G * dt
    pos = np.zeros((len(z), 1, 3))
    pos[:, 0, 2] = np.array(z) + r
    vel = np.zeros_like(pos)
    vel[:, 0, 2] = vz
    pred = Trajectory.__new__(Trajectory)
    pred.pos, pred.vel = pos, vel
    first_up = 3
    expected = z[first_up] + vz[first_up] ** 2 / (2 * G) - dt * vz[first_up] / 2
    assert _first_apex(pred, r, dt) == pytest.approx(expected)


def test_bounce_rows_measure_each_material_and_pybullet():
    materials = [[0.7, 0.5, 0.0, 0.0], [0.3, 0.5, 0.0, 0.0]]
    rows = bounce_rows("reflect", Reflecting(), materials, height=5.0, dt=0.1, radius=0.5)
    assert [r["restitution"] for r in rows] == [0.7, 0.3]
    for r in rows:
        assert r["diverged_at"] is None and r["apex"] > 0
        assert r["ratio"] == pytest.approx(r["apex"] / (r["restitution"] ** 2 * 5.0))
        assert r["truth_ratio"] == pytest.approx(1.0, abs=0.05)  # pybullet keeps e²
    # the reflecting oracle bounces higher for the livelier material
    assert rows[0]["apex"] > rows[1]["apex"]


def test_bounce_section_and_csv_round_trip(tmp_path):
    rows = [
        dict(
            run="a",
            restitution=0.5,
            height=10.0,
            apex=2.4,
            ratio=0.96,
            truth_ratio=1.0,
            diverged_at=None,
        )
    ]
    path = bounce.write_csv(tmp_path / "bounce.csv", rows)
    back = bounce.read_csv(path)
    assert back[0]["ratio"] == pytest.approx(0.96) and back[0]["diverged_at"] is None
    text = bounce.section(back)
    assert "0.96" in text and "`a`" in text
    assert "No bounce" in bounce.section([])


def test_no_bounce_is_nan():
    pred = Trajectory.__new__(Trajectory)
    pred.pos = np.zeros((5, 1, 3))
    pred.pos[:, 0, 2] = [5.0, 4.0, 3.0, 2.0, 1.0]
    pred.vel = np.full((5, 1, 3), -10.0)
    assert np.isnan(_first_apex(pred, 0.5, 0.1))
