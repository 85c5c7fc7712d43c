"""Trivial simulators with the learned simulator's call: ``sim(state) -> (v_{t+1}, ω_{t+1})``.

- :class:`StaticSimulator`: nothing moves (``v̂ = 0``, ``ω̂ = 0``).
- :class:`GravityOnlySimulator`: free fall without contacts, ``v̂ = v_t + g·dt`` in scenes with
  the gravity effect (``v̂ = v_t`` otherwise), ``ω̂ = ω_t``.

Both need no history (``H = history = 0``) and have no parameters.
"""

from __future__ import annotations

import torch
from torch import nn

from physgnn.data.state import scene_of_sphere
from physgnn.physics.scene import EFFECT_NAMES, GRAVITY

_GRAVITY = EFFECT_NAMES.index("gravity")


class StaticSimulator(nn.Module):
    """Predicts that nothing moves: ``(0 [N, 3], 0 [N, 3])``."""

    H = history = 0

    def forward(self, state) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.zeros_like(state.pos), torch.zeros_like(state.pos)


class GravityOnlySimulator(nn.Module):
    """Free fall: ``v̂ = v_t + g·dt`` (gravity effect on), ``ω̂ = ω_t``; no contact at all."""

    H = history = 0

    def __init__(self, gravity: tuple[float, float, float] = GRAVITY):
        super().__init__()
        self.gravity = tuple(float(x) for x in gravity)

    def forward(self, state) -> tuple[torch.Tensor, torch.Tensor]:
        on = state.effects[scene_of_sphere(state), _GRAVITY].to(state.pos.dtype)  # [N]
        g = torch.tensor(self.gravity, dtype=state.pos.dtype, device=state.pos.device)
        vel_next = state.vel[:, 0] + (on * state.scene_dt)[:, None] * g
        return vel_next, state.angvel[:, 0].clone()
