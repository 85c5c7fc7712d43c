"""Quaternion maths: hard cases (identity, half turns, unnormalised input) and properties."""

from __future__ import annotations

import math

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from physgnn.physics import quaternion as Q

F64 = torch.float64
unit = st.floats(-1.0, 1.0, allow_nan=False)
quats = st.lists(unit, min_size=4, max_size=4).filter(lambda v: math.hypot(*v) > 0.1)
# rotation vectors of angle < π − 1e-3 (the log is only single-valued below a half turn)
rotvecs = st.lists(st.floats(-1.8, 1.8, allow_nan=False), min_size=3, max_size=3).filter(
    lambda v: math.hypot(*v) < math.pi - 1e-3
)
FAST = settings(max_examples=60, deadline=None)


def t64(values) -> torch.Tensor:
    return torch.tensor(values, dtype=F64)


def same_rotation(a: torch.Tensor, b: torch.Tensor, atol: float) -> None:
    """``a`` equals ``b`` or ``−b`` (the same rotation)."""
    sign = 1.0 if float((a * b).sum()) >= 0 else -1.0
    torch.testing.assert_close(a, sign * b, atol=atol, rtol=0)


def test_log_of_identity_is_exactly_zero_with_finite_gradient():
    for dtype in (torch.float32, F64):
        q = Q.identity(3, dtype=dtype).requires_grad_()
        out = Q.log(q)
        assert torch.equal(out, torch.zeros(3, 3, dtype=dtype))
        out.sum().backward()
        assert bool(torch.isfinite(q.grad).all())


def test_log_of_exact_half_turn_and_of_its_negative():
    for axis in ([0.0, 0, 1], [0.6, -0.8, 0], [0, -1.0, 0]):
        q = t64([0.0, *axis])
        expected = math.pi * t64(axis)
        # the canonical sign makes the first non-zero axis component positive
        expected = expected if [a for a in axis if a != 0][0] > 0 else -expected
        torch.testing.assert_close(Q.log(q), expected, atol=1e-15, rtol=0)
        torch.testing.assert_close(Q.log(-q), Q.log(q), atol=0, rtol=0)
    rotvec = t64([math.pi, 0, 0])  # exp gives w = cos(π/2) ≈ 6e-17, not exactly 0
    torch.testing.assert_close(Q.log(Q.exp(rotvec)), rotvec, atol=1e-15, rtol=0)


def test_log_just_below_a_half_turn():
    angle = math.pi - 1e-7
    axis = t64([2.0, -1.0, 2.0]) / 3.0
    rotvec = Q.log(Q.exp(angle * axis))
    torch.testing.assert_close(rotvec.norm(), t64(angle), atol=1e-14, rtol=0)
    torch.testing.assert_close(rotvec / rotvec.norm(), axis, atol=1e-12, rtol=0)
    # float32 cannot tell π − 1e-7 from π (ulp(π) = 2.4e-7): the angle is right to that ulp.
    q32 = Q.exp((angle * axis).float())
    got = Q.log(q32).norm().double()
    assert abs(float(got) - angle) < 4e-7
    torch.testing.assert_close(Q.log(-q32), Q.log(q32), atol=0, rtol=0)


def test_rotation_past_a_half_turn_takes_the_shortest_arc():
    axis = t64([0.0, 0, 1])
    got = Q.log(Q.exp((math.pi + 0.25) * axis))
    torch.testing.assert_close(got, -(math.pi - 0.25) * axis, atol=1e-14, rtol=0)


@FAST
@given(quats, st.floats(0.01, 100.0))
def test_log_ignores_scale_and_sign(values, scale):
    q = Q.normalize(t64(values))
    ref = Q.log(q)
    torch.testing.assert_close(Q.log(scale * q), ref, atol=1e-13, rtol=0)
    torch.testing.assert_close(Q.log(-q), ref, atol=0, rtol=0)
    assert float(ref.norm()) <= math.pi + 1e-12


@FAST
@given(rotvecs)
def test_exp_log_round_trip(values):
    v = t64(values)
    q = Q.exp(v)
    torch.testing.assert_close(q.norm(), t64(1.0), atol=1e-15, rtol=0)
    torch.testing.assert_close(Q.log(q), v, atol=1e-13, rtol=0)


@FAST
@given(quats)
def test_log_exp_round_trip_up_to_sign(values):
    q = Q.normalize(t64(values))
    same_rotation(Q.exp(Q.log(q)), q, atol=1e-13)


@FAST
@given(quats, rotvecs, st.floats(0.001, 1.0))
def test_angular_velocity_inverts_a_world_frame_rotation(values, omega_dt, dt):
    q_prev = Q.normalize(t64(values))
    omega = t64(omega_dt) / dt
    q_next = Q.multiply(Q.exp(omega * dt), q_prev)
    torch.testing.assert_close(Q.angular_velocity(q_prev, q_next, dt), omega, atol=1e-10, rtol=0)
    torch.testing.assert_close(Q.angular_velocity(q_prev, -q_next, dt), omega, atol=1e-10, rtol=0)


@FAST
@given(quats, quats)
def test_geodesic_angle_is_symmetric_and_bounded(a, b):
    qa, qb = Q.normalize(t64(a)), Q.normalize(t64(b))
    ab, ba = Q.geodesic_angle(qa, qb), Q.geodesic_angle(qb, qa)
    torch.testing.assert_close(ab, ba, atol=1e-12, rtol=0)
    assert 0.0 <= float(ab) <= math.pi + 1e-12
    torch.testing.assert_close(Q.geodesic_angle(qa, -qa), t64(0.0), atol=1e-7, rtol=0)


def test_geodesic_angle_of_a_known_rotation():
    q = Q.exp(t64([0.0, 0.0, 1.25]))
    torch.testing.assert_close(Q.geodesic_angle(q, Q.identity(dtype=F64)), t64(1.25))


def test_multiply_identity_inverse_and_a_known_product():
    i, j, k = t64([0.0, 1, 0, 0]), t64([0.0, 0, 1, 0]), t64([0.0, 0, 0, 1])
    torch.testing.assert_close(Q.multiply(i, j), k)  # Hamilton: ij = k
    torch.testing.assert_close(Q.multiply(j, i), -k)
    q = Q.normalize(t64([0.3, -0.5, 0.2, 0.7]))
    torch.testing.assert_close(Q.multiply(q, Q.conjugate(q)), Q.identity(dtype=F64))
    torch.testing.assert_close(Q.multiply(Q.identity(dtype=F64), q), q)


def test_normalize_zero_gives_identity():
    out = Q.normalize(torch.zeros(2, 4))
    torch.testing.assert_close(out, Q.identity(2))


def test_integrating_constant_omega_for_10000_steps_stays_unit():
    omega = torch.tensor([[0.0, 0.0, 3.0], [40.0, -25.0, 10.0], [1e-6, 0.0, 0.0]])
    q = Q.identity(3)
    for _ in range(10_000):
        q = Q.integrate(q, omega, 1e-3)
    torch.testing.assert_close(q.norm(dim=-1), torch.ones(3), atol=1e-6, rtol=0)


def test_integration_rotates_by_the_exact_step_angle():
    # One step is normalise((1, ½·dt·ω) ⊗ q): a rotation by exactly 2·atan(|ω|·dt/2) about ω.
    dt, steps = 1e-3, 2_000
    q = Q.identity(dtype=F64)
    for _ in range(steps):
        q = Q.integrate(q, t64([0.0, 0.0, 3.0]), dt)
    angle = steps * 2 * math.atan(3.0 * dt / 2)
    same_rotation(q, t64([math.cos(angle / 2), 0, 0, math.sin(angle / 2)]), atol=1e-12)


def test_xyzw_round_trip_and_order():
    q = torch.tensor([[0.1, 0.2, 0.3, 0.4]])
    torch.testing.assert_close(Q.to_xyzw(q), torch.tensor([[0.2, 0.3, 0.4, 0.1]]))
    torch.testing.assert_close(Q.from_xyzw(Q.to_xyzw(q)), q)
    torch.testing.assert_close(Q.to_xyzw(Q.from_xyzw(q)), q)


def test_log_of_a_half_turn_with_a_denormal_component_ignores_scale():
    # a denormal that rescaling flushes to 0 must not choose the half turn's sign
    q = Q.normalize(t64([0.0, 0.0, -5e-324, 1.0]))
    torch.testing.assert_close(Q.log(0.5 * q), Q.log(q), atol=1e-13, rtol=0)
    torch.testing.assert_close(Q.log(-q), Q.log(q), atol=0, rtol=0)
