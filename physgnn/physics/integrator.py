"""Semi-implicit Euler integration of predicted velocities (physics side, no network)."""

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
