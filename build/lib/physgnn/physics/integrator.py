"""Semi-implicit Euler integration of predicted velocities, and one whole frame of a rollout."""

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
    dt_col = dt.unsqueeze(-1) if torch.is_tensor(dt) else dt
    pos_next = pos + dt_col * vel_next
    if rotate is False:
        return pos_next, quat
    quat_next = Q.integrate(quat, angvel_next, dt_col)
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
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """One frame of a rollout: :func:`euler_step`, then ``hold(pos, quat, pos_next,
    quat_next)`` (optional) may keep spheres in place, then the velocity histories are
    shifted by the velocities the move implies, ``(p_{t+1} − p_t)/dt`` and
    ``log(q_{t+1} ⊗ q_t⁻¹)/dt``, exactly as the training features are computed.

    pos ``[N, 3]``, quat ``[N, 4]``, vel / angvel ``[N, H+1, 3]`` (latest first), the
    predicted vel_next / angvel_next ``[N, 3]``, dt ``[N]``. Returns the next
    ``(pos, quat, vel, angvel)``.
    """
    pos_next, quat_next = euler_step(pos, quat, vel_next, angvel_next, dt, rotate)
    if hold is not None:
        pos_next, quat_next = hold(pos, quat, pos_next, quat_next)
    vel_new = (pos_next - pos) / dt[:, None]
    if rotate is False and hold is None:
        angvel_new = torch.zeros_like(vel_new)  # orientation untouched
    else:
        angvel_new = Q.angular_velocity(quat, quat_next, dt[:, None])
    return pos_next, quat_next, shift(vel, vel_new), shift(angvel, angvel_new)
