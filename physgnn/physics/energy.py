"""Mechanical energy of spheres (physics side).

Potential energy is measured from the ground *contact height*: ``m·g·(z − r)``, so a sphere
resting on the ground has zero energy. Rotational energy is not included (as in the report).
"""

from __future__ import annotations

import torch

from physgnn.physics.scene import GRAVITY

G = -GRAVITY[2]  # m/s², the scenes' default gravity


def sphere_energy(
    pos: torch.Tensor, vel: torch.Tensor, mass: torch.Tensor, radius: torch.Tensor, g: float = G
) -> torch.Tensor:
    """Kinetic + potential energy of each sphere. ``[..., N, 3]`` → ``[..., N]`` (joules)."""
    kinetic = 0.5 * mass * (vel * vel).sum(-1)
    potential = mass * g * (pos[..., 2] - radius)
    return kinetic + potential


def scene_energy(
    pos: torch.Tensor,
    vel: torch.Tensor,
    mass: torch.Tensor,
    radius: torch.Tensor,
    batch: torch.Tensor,
    num_scenes: int,
    g: float = G,
) -> torch.Tensor:
    """Total energy of each scene of a batch. pos, vel ``[N, 3]``, batch ``[N]`` → ``[B]``."""
    per_sphere = sphere_energy(pos, vel, mass, radius, g)
    return per_sphere.new_zeros(num_scenes).index_add_(0, batch, per_sphere)


def scene_weight(
    mass: torch.Tensor, batch: torch.Tensor, num_scenes: int, g: float = G
) -> torch.Tensor:
    """Total weight ``Σ m·g`` of each scene ``[B]``: divides an energy into metres of height,
    so an energy penalty means the same in scenes of any size."""
    return mass.new_zeros(num_scenes).index_add_(0, batch, mass * g)
