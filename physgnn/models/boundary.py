"""GNS-style boundary features (``boundary_features=True``, the GNS-style baseline that has no
ps edges): as in GNS (Sanchez-Gonzalez et al. 2020), every sphere sees how far the boundaries
are along the 6 axis directions, so the network sees the ground and the walls without surface
edges."""

from __future__ import annotations

import torch

from physgnn.data.state import scene_of_sphere

# The 6 axis directions of the boundary features, in order +x, −x, +y, −y, +z, −z.
DIRECTIONS = torch.tensor(
    [[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0]]
)


def boundary_features(state, radius: float) -> torch.Tensor:
    """``[N, 6]``: for each direction d of :data:`DIRECTIONS` (+x, −x, +y, −y, +z, −z), the
    height ``h = n·(p − p_0) − r`` of the sphere's surface above the nearest plane of its
    scene whose inward normal n is closest to d (``argmax_d n·d``, the first on a tie: the
    ground, +z; a wall facing −x, −x; a ramp tilted 30°, +z), as ``clip(h, 0, R) / R`` with
    R = ``radius`` (m). Planes are infinite, a sphere behind one gives 0, and 1 means no such
    plane within R."""
    planes = state.planes.to(state.pos.dtype)
    normal = planes[:, 3:6]
    slot = (normal @ DIRECTIONS.to(normal).T).argmax(1)  # [S]
    offset = state.pos[:, None, :] - planes[None, :, 0:3]  # [N, S, 3]
    height = (offset * normal).sum(-1) - state.radius[:, None]  # [N, S]
    height = height.clamp(0.0, radius) / radius
    same = scene_of_sphere(state)[:, None] == state.plane_batch.long()[None, :]
    height = torch.where(same, height, torch.ones_like(height))
    out = height.new_ones(height.shape[0], len(DIRECTIONS))
    return out.scatter_reduce(1, slot.expand_as(height), height, "amin")
