"""Contact constraints on predicted positions: no sphere inside another, none behind a plane.

:func:`project_contacts` moves the predicted next positions ``x`` (``p_t + dt·v̂``) of spheres
so that, on the given pp pairs and ps edges, no pair overlaps more than it does now and no
sphere reaches further into a plane than it does now (position-based dynamics). Each of the
``iterations`` runs one Jacobi pass over the pairs (every violated pair proposes a correction),
then one over the plane edges (each sphere put back on the allowed side of its planes), so
that every iteration ends with the planes kept: a pile pushed into the ground by its pairs is
lifted at once, not by halves. A sphere moves by the mean of its proposals weighted by their
squared lengths, ``Σ|Δ|²Δ / Σ|Δ|²``: never further than its longest proposal (as the plain
mean), but its deepest violation leads, and contacts grazed by rounding do not halve it (the
plain mean leaves a sphere pressed into a wall and resting on the ground halfway in after a
pass, and needs about twice the iterations for the same depth in the OOD cube scenes).

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
  comes from behind a ramp, beside its edge, is never lifted onto it: such a sphere (behind
  the infinite plane, beside the rectangle now) meets the rectangle's edge alone, ``dist``
  the unsigned distance to the rectangle wherever the prediction takes it (as the
  penetration metric counts it), so it is kept off the edge without being put in front.

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
    ps_active: torch.Tensor | None = None,
) -> torch.Tensor:
    """Corrected predicted positions ``[N, 3]`` (module doc).

    pos ``[N, 3]`` (now), pos_next ``[N, 3]`` (predicted), radius, mass ``[N]``, pairs ``[2, P]``
    (each unordered pair once), planes ``[S, 11]``, plane_kind ``[S]``, ps_index ``[2, F]``
    (row 0 plane, row 1 sphere), ``ps_active [F]`` (bool, default all): the ps edges that
    count (a mask, not a compaction: nothing is read back).
    """
    x = pos_next.clone()
    if iterations < 1 or pos.shape[0] == 0:
        return x
    i, j = pairs
    pos_i, pos_j = pos.index_select(0, i), pos.index_select(0, j)
    reach = radius.index_select(0, i) + radius.index_select(0, j)
    pair_target = torch.minimum(reach, (pos_i - pos_j).norm(dim=1))
    w_i, w_j = 1.0 / mass.index_select(0, i), 1.0 / mass.index_select(0, j)
    share = w_i / (w_i + w_j)  # [P]
    ends, weight = torch.cat([i, j]), torch.cat([-share, 1 - share])[:, None]  # [2P]
    plane, sphere = ps_index
    frames = _PlaneFrames(
        planes.index_select(0, plane), plane_kind.index_select(0, plane), pos.dtype
    )
    centres = pos.index_select(0, sphere)
    front = frames.in_front(centres)  # of the infinite plane
    dist_now, _, over, length = frames.distance(centres)
    unsigned = ~front & ~over  # behind the plane, beside the rectangle: its edge only
    frames.keep_sign = ~unsigned
    dist_now = torch.where(frames.keep_sign, dist_now, length)
    active = front | unsigned
    if ps_active is not None:
        active = active & ps_active
    active = active.to(pos_next.dtype)  # [F] 0/1
    plane_target = torch.minimum(radius.index_select(0, sphere), dist_now)
    for _ in range(iterations):
        x = _pair_pass(x, i, j, ends, weight, pair_target)
        x = _plane_pass(x, sphere, frames, active, plane_target)
    return x


def _pair_pass(x, i, j, ends, weight, target) -> torch.Tensor:
    """One Jacobi pass over the pairs: every violated pair proposes its correction to both
    spheres (:func:`_combine`)."""
    d = x.index_select(0, i) - x.index_select(0, j)
    length = d.norm(dim=1)
    c = length - target
    # only violated pairs (c < 0) propose; coincident centres (length 0) have d = 0
    step = (c / length.clamp_min(1e-12)).clamp(max=0.0)[:, None] * d  # C·n̂
    return _combine(x, ends, step.repeat(2, 1) * weight)


def _plane_pass(x, sphere, frames, active, target) -> torch.Tensor:
    """Every violated plane edge proposes to put its sphere back on the allowed side (planes
    do not move; :func:`_combine`)."""
    dist, direction, _, _ = frames.distance(x.index_select(0, sphere))
    push = (target - dist).clamp(min=0.0) * active  # −C of the violated active edges
    return _combine(x, sphere, push[:, None] * direction)


def _combine(x, index, proposals) -> torch.Tensor:
    """``x`` moved by the proposals ``[K, 3]`` for spheres ``index [K]``: each sphere by their
    mean weighted by their squared lengths, ``Σ|Δ|²Δ / Σ|Δ|²`` (a zero proposal counts
    nothing; a sphere with none is left exactly as it is)."""
    weight = (proposals * proposals).sum(1, keepdim=True)
    acc = x.new_zeros(x.shape[0], 4).index_add_(
        0, index, torch.cat([proposals * weight, weight], 1)
    )
    return x + acc[:, :3] / acc[:, 3:].clamp_min(1e-30)  # no proposal: 0 / 1e-30


class _PlaneFrames:
    """The rows of ``F`` plane edges with their in-plane axes, in the points' dtype, for the
    distances of points to them (as :func:`~physgnn.physics.geometry.rectangle_offset`, in a
    form of few operations: it runs in every iteration)."""

    def __init__(self, rows: torch.Tensor, kind: torch.Tensor, dtype: torch.dtype):
        rows = rows.to(dtype)
        self.centre, self.normal, ref = rows[:, 0:3], rows[:, 3:6], rows[:, 6:9]
        other = torch.linalg.cross(self.normal, ref)
        self.basis = torch.stack([ref, other, self.normal], 1)  # [F, 3, 3]: rows u, w, n
        self.half = torch.stack([rows[:, 9], rows[:, 10], torch.zeros_like(rows[:, 9])], 1)
        self.minus_half = -self.half
        self.ground = kind == GROUND
        self.keep_sign = torch.ones_like(self.ground)  # [F] bool; False: the rectangle's distance

    def in_front(self, points: torch.Tensor) -> torch.Tensor:
        """``[F]`` bool: centres on the front side of the infinite plane."""
        return ((points - self.centre) * self.normal).sum(1) >= 0

    def distance(self, points: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """``(dist [F], direction [F, 3], over [F] bool, length [F])``: the signed height along
        the normal over the rectangle (the ground: everywhere) where ``keep_sign``, else the
        distance to the rectangle (``length``) and the unit direction from it to the point;
        ``over``: the point is over the rectangle's footprint."""
        local = (self.basis * (points - self.centre)[:, None, :]).sum(-1)  # [F, 3]: u, w, h
        local = local - torch.clamp(local, self.minus_half, self.half)  # from the nearest point
        over = self.ground | (local[:, :2].norm(dim=1) <= 1e-6)
        signed = over & self.keep_sign
        length = local.norm(dim=1)
        dist = torch.where(signed, local[:, 2], length)
        away = (local[:, :, None] * self.basis).sum(1) / length.clamp_min(1e-12)[:, None]
        direction = torch.where(signed[:, None], self.normal, away)
        return dist, direction, over, length
