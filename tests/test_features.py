"""Finite-difference velocities and history: hand-computed values and float32 error bounds.

Stated float32 error bounds (u = 2^-24, the float32 unit roundoff), against a float64
reference computed from the unrounded float64 trajectory:

- linear velocity, per component: ``|v32 − v64| ≤ 2u·max(|p_k|, |p_{k−1}|)/dt + 4u·|v64|``
  (rounding both positions to float32, then the subtraction and the division); e.g.
  ≤ 1.3e-4 m/s for positions up to 100 m at dt = 0.1 s;
- angular velocity: ``|ω32 − ω64| ≤ 64u/dt`` (≈ 3.8e-5 rad/s at dt = 0.1 s) for relative
  rotations per frame up to 2.5 rad (quaternion rounding ≈ 2u per component, amplified by the
  product and by the logarithm's factor 2·(θ/2)/sin(θ/2) ≤ π); near a half turn per frame the
  sign of ω is undecidable and no bound holds.
"""

from __future__ import annotations

import math

import pytest
import torch

from physgnn.physics import quaternion as Q
from physgnn.physics.kinematics import finite_difference_velocities, history

U32 = 2.0**-24


def about_z(angle: float) -> list[float]:
    return [math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)]


def test_finite_differences_by_hand():
    pos = torch.tensor(
        [
            [[0.0, 0, 0], [5, 5, 5]],
            [[1.0, 2, 3], [5, 5, 5]],
            [[1.0, 2, 5], [5, 5, 5]],
        ]
    )
    quat = torch.tensor(
        [
            [about_z(0.0), [1.0, 0, 0, 0]],
            [about_z(0.25), [1.0, 0, 0, 0]],
            # the engine may hand back −q: the same orientation, so the same ω
            [[-c for c in about_z(0.5)], [1.0, 0, 0, 0]],
        ]
    )
    vel0 = torch.tensor([[7.0, 0, 0], [0, 0, -1]])
    angvel0 = torch.tensor([[0.0, 9, 0], [0, 0, 0]])
    vel, angvel = finite_difference_velocities(pos, quat, vel0, angvel0, dt=0.5)
    expected_vel = torch.tensor(
        [
            [[7.0, 0, 0], [0, 0, -1]],
            [[2.0, 4, 6], [0, 0, 0]],
            [[0.0, 0, 4], [0, 0, 0]],
        ]
    )
    torch.testing.assert_close(vel, expected_vel)
    expected_angvel = torch.tensor(
        [
            [[0.0, 9, 0], [0, 0, 0]],
            [[0.0, 0, 0.5], [0, 0, 0]],  # 0.25 rad per 0.5 s about z
            [[0.0, 0, 0.5], [0, 0, 0]],
        ]
    )
    torch.testing.assert_close(angvel, expected_angvel)


def test_angular_velocity_of_a_half_turn_per_frame_is_finite():
    quat = torch.tensor([[[1.0, 0, 0, 0]], [[0.0, 1, 0, 0]]])  # π about x in one frame
    _, angvel = finite_difference_velocities(
        torch.zeros(2, 1, 3), quat, *[torch.zeros(1, 3)] * 2, 1.0
    )
    torch.testing.assert_close(angvel[1], torch.tensor([[math.pi, 0, 0]]))


def test_history_is_latest_first_by_hand():
    series = torch.arange(4.0).reshape(4, 1, 1).expand(4, 2, 3)  # value = frame index
    h = history(series, t=3, h=2)
    assert h.shape == (2, 3, 3)
    torch.testing.assert_close(h[0, :, 0], torch.tensor([3.0, 2.0, 1.0]))
    torch.testing.assert_close(history(series, t=1, h=0), series[1].unsqueeze(1))
    torch.testing.assert_close(history(series, t=2, h=2)[1, :, 2], torch.tensor([2.0, 1.0, 0.0]))
    with pytest.raises(IndexError, match="fewer than 2 predecessors"):
        history(series, t=1, h=2)


def reference_trajectory(dt: float, frames: int = 40, n: int = 64):
    """Ballistic spheres up to ~100 m away, spinning at up to 2.5 rad per frame, float64."""
    gen = torch.Generator().manual_seed(9)
    t = torch.arange(frames, dtype=torch.float64)[:, None, None] * dt
    p0 = (torch.rand(n, 3, generator=gen, dtype=torch.float64) * 2 - 1) * 60
    p0[:, 2] = p0[:, 2].abs() + 40
    v0 = torch.randn(n, 3, generator=gen, dtype=torch.float64) * 10
    g = torch.tensor([0, 0, -9.81], dtype=torch.float64)
    pos = p0 + v0 * t + 0.5 * g * t**2
    axis = torch.nn.functional.normalize(torch.randn(n, 3, generator=gen, dtype=torch.float64))
    rate = torch.rand(n, 1, generator=gen, dtype=torch.float64) * 2.5 / dt
    rate[:4] = 1e-4  # nearly resting spheres too
    q0 = Q.normalize(torch.randn(n, 4, generator=gen, dtype=torch.float64))
    quat = Q.multiply(Q.exp(axis * rate * t), q0)
    return pos, quat, v0, axis * rate


@pytest.mark.parametrize("dt", [0.1, 0.01])
def test_float32_against_float64_reference_within_stated_bounds(dt):
    pos, quat, v0, w0 = reference_trajectory(dt)
    v64, w64 = finite_difference_velocities(pos, quat, v0, w0, dt)
    v32, w32 = finite_difference_velocities(pos.float(), quat.float(), v0.float(), w0.float(), dt)
    assert v32.dtype == torch.float32
    scale = torch.maximum(pos[1:].abs(), pos[:-1].abs())
    bound_v = 2 * U32 * scale / dt + 4 * U32 * v64[1:].abs()
    assert bool(((v32[1:].double() - v64[1:]).abs() <= bound_v).all())
    err_w = (w32[1:].double() - w64[1:]).abs().max()
    assert float(err_w) <= 64 * U32 / dt
    # the bounds are not loose by orders of magnitude
    assert float(((v32[1:].double() - v64[1:]).abs() / bound_v).max()) > 0.05
    assert float(err_w) > 64 * U32 / dt / 100
