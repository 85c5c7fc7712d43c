"""Free fall against ½gt² (physgnn.evaluation.freefall) and its report section."""

import math

import numpy as np
import pytest
import torch

from physgnn.evaluation.freefall import free_fall, free_seconds, freefall_rows
from physgnn.models.baselines import GravityOnlySimulator
from physgnn.report import freefall as report

G, DT = 9.81, 0.1


def test_analytic_trajectory_is_the_parabola():
    traj = free_fall(100.0, 4.0, DT)
    assert traj.n_frames == 41 and traj.n_spheres == 1
    t = np.arange(41) * DT
    np.testing.assert_allclose(traj.pos[:, 0, 2], 100.0 - 0.5 * G * t**2)
    np.testing.assert_allclose(traj.vel[:, 0, 2], -G * t)


def test_gravity_only_lags_the_parabola_by_its_first_order_term_at_every_height():
    # Semi-implicit Euler from rest (H = 0): z_k = h − g·dt²·k(k+1)/2, i.e. ½gt² + g·dt·t/2.
    heights = [100.0, 1000.0]
    rows = freefall_rows("gravity", GravityOnlySimulator(), heights, 4.0, DT, dtype=torch.float64)
    assert [r["height"] for r in rows] == [100.0, 1000.0]
    for row in rows:
        assert row["seconds"] == pytest.approx(4.0)
        assert row["z_error"] == pytest.approx(G * DT * 4.0 / 2, rel=1e-4)
        assert row["z_error_pct"] == pytest.approx(100 * (G * DT * 2.0) / (0.5 * G * 16), rel=1e-4)
        # From recorded positions (float32: 6e-5 m apart near 1 000 m, over dt).
        assert row["dvz_first"] == pytest.approx(-G * DT, abs=1e-3)
        assert row["z_true"] == pytest.approx(row["height"] - 0.5 * G * 16)


def test_the_fall_stops_short_of_the_floor():
    assert free_seconds(100.0, 4.0, DT, floor=5.0) == 4.0
    assert free_seconds(10.0, 4.0, DT, floor=5.0) == pytest.approx(1.0)  # 4.9 m fallen at 1 s
    assert free_seconds(5.0, 4.0, DT, floor=5.0) == 0.0
    (row,) = freefall_rows("gravity", GravityOnlySimulator(), [10.0], 4.0, DT)
    assert row["seconds"] == pytest.approx(1.0) and row["z_true"] == pytest.approx(10 - G / 2)


def test_section_lists_every_row_and_the_free_flight_step(tmp_path):
    rows = freefall_rows("gravity_only", GravityOnlySimulator(), [10.0], 4.0, DT)
    path = report.write_csv(tmp_path / "freefall.csv", rows)
    back = report.read_csv(path)
    assert back[0]["z_error"] == pytest.approx(rows[0]["z_error"])
    text = report.section(back)
    assert "`gravity_only`" in text and "-0.981 m/s at dt = 0.1 s" in text
    assert "No free-fall" in report.section([])
    assert math.isfinite(back[0]["dvz_first"])
