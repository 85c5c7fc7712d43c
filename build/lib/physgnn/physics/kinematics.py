"""Per-sphere kinematic features from positions and orientations (physics side, no network).

Velocities are finite differences of frames: ``v_k = (p_k − p_{k−1}) / dt`` and
``ω_k = log(q_k ⊗ q_{k−1}⁻¹) / dt`` (world frame, shortest arc). Frame 0 has no predecessor,
so ``v_0, ω_0`` are the scene's initial (engine) velocities: the first ``H + 1`` frames are
then enough to start a rollout with a history of ``H + 1`` velocities.
"""

from __future__ import annotations

import torch

from physgnn.physics import quaternion as Q


def finite_difference_velocities(
    pos: torch.Tensor, quat: torch.Tensor, vel0: torch.Tensor, angvel0: torch.Tensor, dt: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Linear and angular velocities of every frame.

    pos ``[T, N, 3]``, quat ``[T, N, 4]``, vel0 / angvel0 ``[N, 3]`` → vel, angvel ``[T, N, 3]``.
    """
    vel = torch.empty_like(pos)
    angvel = torch.empty_like(pos)
    vel[0], angvel[0] = vel0, angvel0
    vel[1:] = (pos[1:] - pos[:-1]) / dt
    angvel[1:] = Q.angular_velocity(quat[:-1], quat[1:], dt)
    return vel, angvel


def history(series: torch.Tensor, t: int, h: int) -> torch.Tensor:
    """The ``h + 1`` latest values up to frame ``t``, latest first.

    series ``[T, N, 3]`` → ``[N, h + 1, 3]`` = ``[x_t, x_{t−1}, …, x_{t−h}]``; needs ``t ≥ h``.
    """
    if t < h:
        raise IndexError(f"frame {t} has fewer than {h} predecessors")
    return series[t - h : t + 1].flip(0).transpose(0, 1).contiguous()
