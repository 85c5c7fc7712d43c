"""Semi-implicit Euler integration of predicted velocities, the exact move of a frame's mean
motion (the engine state), and one whole frame of a rollout."""

from __future__ import annotations

import torch

from physgnn.physics import quaternion as Q


def euler_step(
    pos: torch.Tensor,
    quat: torch.Tensor,
    vel_next: torch.Tensor,
    angvel_next: torch.Tensor,
    dt: torch.Tensor | float,
    rotate: torch.Tensor | bool = True,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``p ← p + dt·v̂``, ``q ← normalise(q + ½·dt·(0, ω̂) ⊗ q)``.

    pos ``[N, 3]``, quat ``[N, 4]``, vel_next / angvel_next ``[N, 3]`` (the predicted
    ``v_{t+1}``, ``ω_{t+1}``, ω in the world frame), dt a float or ``[N]``. ``rotate`` (bool or
    ``[N]`` bool) leaves the orientation of the other spheres bit-identical.
    Returns ``(pos_next [N, 3], quat_next [N, 4])``.
    """
    return _advance(pos, quat, vel_next, dt, rotate, lambda h: Q.integrate(quat, angvel_next, h))


def move(
    pos: torch.Tensor,
    quat: torch.Tensor,
    mean_vel: torch.Tensor,
    mean_angvel: torch.Tensor,
    dt: torch.Tensor | float,
    rotate: torch.Tensor | bool = True,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``p ← p + dt·ū``, ``q ← exp(dt·ω̄) ⊗ q``: the frame's mean motion ``ū = Δp/dt``,
    ``ω̄ = log(q_{t+1} ⊗ q_t⁻¹)/dt`` undone exactly (the inverse of the finite differences of
    :func:`~physgnn.physics.kinematics.finite_difference_velocities`).

    Shapes as :func:`euler_step`; ``rotate`` leaves the other spheres' orientation
    bit-identical."""

    def turn(h):
        return Q.normalize(Q.multiply(Q.exp(h * mean_angvel), quat))

    return _advance(pos, quat, mean_vel, dt, rotate, turn)


def _advance(pos, quat, vel, dt, rotate, turn) -> tuple[torch.Tensor, torch.Tensor]:
    """``(pos + dt·vel, turn(dt))``, ``dt`` a column for ``turn``; the orientation of spheres
    that ``rotate`` (bool or ``[N]`` bool) leaves out stays bit-identical."""
    dt_col = dt.unsqueeze(-1) if torch.is_tensor(dt) else dt
    pos_next = pos + dt_col * vel
    if rotate is False:
        return pos_next, quat
    quat_next = turn(dt_col)
    if rotate is not True:
        quat_next = torch.where(rotate.unsqueeze(-1), quat_next, quat)
    return pos_next, quat_next


def shift(history: torch.Tensor, latest: torch.Tensor) -> torch.Tensor:
    """``[N, H+1, 3]`` history (latest first) with ``latest [N, 3]`` pushed in front."""
    return torch.cat([latest[:, None], history[:, :-1]], dim=1)


def step(
    pos: torch.Tensor,
    quat: torch.Tensor,
    vel: torch.Tensor,
    angvel: torch.Tensor,
    vel_next: torch.Tensor,
    angvel_next: torch.Tensor,
    dt: torch.Tensor,
    rotate: torch.Tensor | bool = True,
    hold=None,
    mean: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """One frame of a rollout, then ``hold(pos, quat, pos_next, quat_next)`` (optional) may
    keep spheres in place.

    - A finite-difference state (``mean`` None): :func:`euler_step`, then the velocity
      histories are shifted by the velocities the move implies, ``(p_{t+1} − p_t)/dt`` and
      ``log(q_{t+1} ⊗ q_t⁻¹)/dt``, exactly as the training features are computed.
    - The engine state (``mean = (ū, ω̄)``, the frame's mean motion): :func:`move` by the mean
      motion, and the histories are shifted by the predicted end-of-frame ``vel_next`` and
      ``angvel_next``; a sphere that ``hold`` kept in place gets zero velocities.

    pos ``[N, 3]``, quat ``[N, 4]``, vel / angvel ``[N, H+1, 3]`` (latest first), the
    predicted vel_next / angvel_next ``[N, 3]``, dt ``[N]``. Returns the next
    ``(pos, quat, vel, angvel)``.
    """
    if mean is not None:
        return _engine_step(pos, quat, vel, angvel, vel_next, angvel_next, dt, rotate, hold, mean)
    pos_next, quat_next = euler_step(pos, quat, vel_next, angvel_next, dt, rotate)
    if hold is not None:
        pos_next, quat_next = hold(pos, quat, pos_next, quat_next)
    vel_new = (pos_next - pos) / dt[:, None]
    if rotate is False and hold is None:
        angvel_new = torch.zeros_like(vel_new)  # orientation untouched
    else:
        angvel_new = Q.angular_velocity(quat, quat_next, dt[:, None])
    return pos_next, quat_next, shift(vel, vel_new), shift(angvel, angvel_new)


def _engine_step(pos, quat, vel, angvel, vel_next, angvel_next, dt, rotate, hold, mean):
    """:func:`step` of the engine state."""
    pos_next, quat_next = move(pos, quat, mean[0], mean[1], dt, rotate)
    if hold is not None:
        moved_pos, moved_quat = pos_next, quat_next
        pos_next, quat_next = hold(pos, quat, pos_next, quat_next)
        held = ((pos_next != moved_pos).any(1) | (quat_next != moved_quat).any(1))[:, None]
        vel_next = torch.where(held, torch.zeros_like(vel_next), vel_next)
        angvel_next = torch.where(held, torch.zeros_like(angvel_next), angvel_next)
    return pos_next, quat_next, shift(vel, vel_next), shift(angvel, angvel_next)
