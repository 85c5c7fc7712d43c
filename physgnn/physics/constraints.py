"""Contact constraints on predicted positions: no sphere inside another, none behind a plane.

:func:`project_contacts` moves the predicted next positions ``x`` (``p_t + dt·v̂``) of spheres
so that, on the given pp pairs and ps edges, no pair overlaps more than it does now and no
sphere reaches further into a plane than it does now (position-based dynamics, Jacobi style:
every violated constraint proposes a correction, each sphere moves by the mean of its
proposals, ``iterations`` times):

- pair (i, j), ``C = |x_i − x_j| − min(r_i + r_j, |p_i − p_j|)``; when ``C < 0``,
  ``Δx_i = −w_i/(w_i + w_j)·C·n̂`` and ``Δx_j = +w_j/(w_i + w_j)·C·n̂`` with ``w = 1/m`` and
  ``n̂`` from j to i: the pair's linear momentum ``m_i Δx_i + m_j Δx_j`` is unchanged;
- plane edge (s, i) of a sphere whose centre is now in front of the plane (``h ≥ 0``):
  ``C = dist(x_i) − min(r_i, dist(p_i))``, with dist the height above the plane where the
  predicted centre is over the rectangle (direction ``n_s``; negative once the centre has
  crossed it, so a sphere that would pass through within one frame is stopped on the front
  face) and the distance to the rectangle's nearest edge point otherwise (direction from that
  point to the centre); when ``C < 0``, ``Δx_i = −C·direction`` (planes do not move). The
  ground is an infinite plane. "In front" is judged on the infinite plane, so a sphere that
  comes from behind a ramp, beside its edge, is never lifted onto it.

Every iteration runs whatever the violations (no value is read back to the host); one with
nothing violated adds exact zeros.

"Not more than now" rather than "not at all" keeps the stage from pushing apart what already
overlaps (which would turn the overlap into speed): started from a state without overlap, no
constraint is violated after the stage, and a violated one only has its closing motion taken
away. The velocities that go with the corrected positions, ``(x − p)/dt``, so only lose
approaching speed. Spheres with no violated constraint are returned untouched, bit for bit.
"""

from __future__ import annotations

import torch

from physgnn.physics.geometry import rectangle_offset
from physgnn.physics.scene import GROUND


def project_contacts(
    pos: torch.Tensor,
    pos_next: torch.Tensor,
    radius: torch.Tensor,
    mass: torch.Tensor,
    pairs: torch.Tensor,
    planes: torch.Tensor,
    plane_kind: torch.Tensor,
    ps_index: torch.Tensor,
    iterations: int,
) -> torch.Tensor:
    """Corrected predicted positions ``[N, 3]`` (module doc).

    pos ``[N, 3]`` (now), pos_next ``[N, 3]`` (predicted), radius, mass ``[N]``, pairs ``[2, P]``
    (each unordered pair once), planes ``[S, 11]``, plane_kind ``[S]``, ps_index ``[2, F]``
    (row 0 plane, row 1 sphere).
    """
    x = pos_next.clone()
    if iterations < 1 or pos.shape[0] == 0:
        return x
    i, j = pairs
    pair_target = torch.minimum(radius[i] + radius[j], (pos[i] - pos[j]).norm(dim=1))
    share = (1.0 / mass[i]) / (1.0 / mass[i] + 1.0 / mass[j])  # [P] w_i / (w_i + w_j)
    plane, sphere = ps_index
    rows = planes[plane].to(pos.dtype)
    dist_now, _ = _plane_distance(pos[sphere], rows, plane_kind[plane])
    front = ((pos[sphere] - rows[:, 0:3]) * rows[:, 3:6]).sum(1) >= 0  # of the infinite plane
    plane_target = torch.minimum(radius[sphere], dist_now)
    for _ in range(iterations):
        shift, count = torch.zeros_like(x), x.new_zeros(x.shape[0])
        d = x[i] - x[j]
        length = d.norm(dim=1)
        c = length - pair_target
        bad = (c < 0) & (length > 0)
        normal = d / length.clamp_min(1e-12)[:, None]
        step = torch.where(bad, c, torch.zeros_like(c))[:, None] * normal
        shift.index_add_(0, i, -share[:, None] * step).index_add_(0, j, (1 - share)[:, None] * step)
        count.index_add_(0, i, bad.to(x.dtype)).index_add_(0, j, bad.to(x.dtype))
        dist, direction = _plane_distance(x[sphere], rows, plane_kind[plane])
        c = dist - plane_target
        bad = front & (c < 0)
        shift.index_add_(0, sphere, -torch.where(bad, c, torch.zeros_like(c))[:, None] * direction)
        count.index_add_(0, sphere, bad.to(x.dtype))
        x = x + shift / count.clamp_min(1.0)[:, None]  # + 0 where nothing is violated: exact
    return x


def _plane_distance(
    points: torch.Tensor, planes: torch.Tensor, kind: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(dist [F], direction [F, 3])`` of points to their planes (module doc): the signed
    height along the normal over the rectangle (the ground: everywhere), else the distance to
    the rectangle and the unit direction from it to the point."""
    normal = planes[:, 3:6]
    offset = rectangle_offset(points, planes).to(points.dtype)  # the ground: along its normal
    height = (offset * normal).sum(1)
    beside = offset - height[:, None] * normal
    over = (kind == GROUND) | (beside.norm(dim=1) <= 1e-6)
    length = offset.norm(dim=1)
    dist = torch.where(over, height, length)
    direction = torch.where(over[:, None], normal, offset / length.clamp_min(1e-12)[:, None])
    return dist, direction
