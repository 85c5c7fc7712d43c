"""Training noise shaped like the errors a rollout feeds back (the doc of
:mod:`physgnn.training.lit` says why), scaled to each sphere's regime."""

from __future__ import annotations

import torch

from physgnn.models.learned import LearnedSimulator
from physgnn.physics import quaternion as Q

# Seeds of DDP process r: r · RANK_STRIDE above process 0's. The CPU generator takes a seed's
# low 32 bits; this odd stride (2³² / golden ratio) keeps the seeds of any two of up to 1 024
# processes at least 1.9 million apart modulo 2³², more steps than any run takes.
RANK_STRIDE = 2_654_435_761


def noise_seed(seed: int, step: int, rank: int = 0) -> int:
    """The seed of the random draws of training step ``step`` in DDP process ``rank``: every
    process draws its own noise, reproducible for (seed, rank, step); process 0 (and a run of
    one process) draws what one process always drew, and rank 0's seed is also what every
    process shares (the push-forward length)."""
    return seed * 1_000_003 + step + rank * RANK_STRIDE


def regime_scale(state, simulator: LearnedSimulator, rest_scale: float) -> torch.Tensor:
    """``[N, 1, 1]``: each sphere's noise factor ``clamp(s / σ_v, rest_scale, 1)``, s its
    speed ``max(|v_t|, |ω_t|·r)`` and σ_v the RMS velocity std: a flying or bouncing sphere gets
    the full noise, a resting one ``rest_scale`` of it, so that rest stays resolvable (1 radius
    of creep over 2 000 frames is 0.0025 m/s; the full noise is 0.005–0.03 m/s)."""
    speed = torch.maximum(
        torch.linalg.vector_norm(state.vel[:, 0], dim=1),
        torch.linalg.vector_norm(state.angvel[:, 0], dim=1) * state.radius,
    )
    return (speed / simulator.speed_scale).clamp(rest_scale, 1.0)[:, None, None]


def add_noise(state, simulator: LearnedSimulator, std: float, generator=None, rest_scale=1.0):
    """A copy of ``state`` with rollout-shaped noise and the matching velocity target (see the
    module doc), velocity noise scaled by :func:`regime_scale` (``rest_scale`` 1: the same for
    every sphere). ``state.vel`` / ``angvel`` are ``[N, H+1, 3]``, latest first."""

    def randn_like(x: torch.Tensor) -> torch.Tensor:
        return torch.randn(x.shape, generator=generator, dtype=x.dtype, device=x.device)

    def random_walk(x: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
        """``[N, H+1, 3]`` cumulative noise from the oldest entry to the latest (std scale)."""
        steps = randn_like(x) * (scale / x.shape[1] ** 0.5)
        return torch.cumsum(steps.flip(1), dim=1).flip(1)

    noisy = state.clone()
    rot = simulator.rotating(state)[:, None]
    dt = state.scene_dt[:, None]
    regime = regime_scale(state, simulator, rest_scale) if rest_scale < 1 else 1.0
    dv = random_walk(state.vel, std * simulator.vel_std * regime)
    noisy.vel = state.vel + dv
    dp = dt * dv.sum(1)  # p̃_t − p_t: the velocity noise integrated along the history
    noisy.pos = state.pos + dp
    if getattr(state, "target_mean_vel", None) is not None:  # the engine state
        noisy.target_mean_vel = state.target_mean_vel - dp / dt
    elif getattr(state, "target_vel", None) is not None:
        noisy.target_vel = state.target_vel - dp / dt
    quat = Q.normalize(state.quat + std * randn_like(state.quat))
    noisy.quat = torch.where(rot, quat, state.quat)
    angvel = state.angvel + random_walk(state.angvel, std * simulator.angvel_std * regime)
    noisy.angvel = torch.where(rot[:, :, None], angvel, state.angvel)
    return noisy
