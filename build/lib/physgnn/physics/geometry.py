"""Spheres against planes, in float64 with the boundary included: one rule for the graph's ps
edges and for the penetration metrics.

A plane row ``[11]`` is centre (3), unit normal (3), unit reference direction (3) and the half
lengths along the reference direction and along normal × reference
(:mod:`physgnn.physics.scene`). The ground (kind 0) is a half-space; every other plane is a
one-sided bounded rectangle (its front faces the normal).
"""

from __future__ import annotations

import torch

from physgnn.physics.scene import GROUND


def rectangle_offset(pos: torch.Tensor, planes: torch.Tensor) -> torch.Tensor:
    """Offset from the closest point of bounded planes to points, float64 ``[..., 3]``.

    pos ``[..., 3]`` and planes ``[..., 11]`` broadcast against each other; infinite half
    lengths (the ground) give the offset from the unbounded plane. Its norm is the distance to
    the rectangle (:func:`rectangle_distance`); its component along the normal is the signed
    height above the plane.
    """
    p, planes = pos.to(torch.float64), planes.to(torch.float64)
    centre, normal, ref = planes[..., 0:3], planes[..., 3:6], planes[..., 6:9]
    other = torch.linalg.cross(normal, ref)
    rel = p - centre
    u, w = (rel * ref).sum(-1), (rel * other).sum(-1)
    h = (rel * normal).sum(-1)
    du = u - torch.clamp(u, -planes[..., 9], planes[..., 9])
    dw = w - torch.clamp(w, -planes[..., 10], planes[..., 10])
    return du[..., None] * ref + dw[..., None] * other + h[..., None] * normal


def rectangle_distance(pos: torch.Tensor, planes: torch.Tensor) -> torch.Tensor:
    """Distance from points to the closest point of bounded planes, float64: the norm of
    :func:`rectangle_offset` (same broadcasting) → ``[...]``."""
    return torch.linalg.vector_norm(rectangle_offset(pos, planes), dim=-1)


def plane_depth(
    pos: torch.Tensor, radius: torch.Tensor, plane: torch.Tensor, kind: int
) -> torch.Tensor:
    """How deep spheres reach into one plane, float64 (> 0: they intersect it).

    pos ``[..., N, 3]``, radius ``[N]``, plane ``[11]`` → ``[..., N]``. Planes are one-sided,
    as the graph sees them: the ground (``kind == GROUND``) is a half-space, ``r − (p − c)·n``;
    other planes are rectangles, ``r − |p − closest point|`` in front of them and ``r + |h|``
    for a centre less than ``r`` behind the rectangle (height ``−r < h < 0`` over its
    footprint: where the graph still gives it an edge). Either way a depth above ``r`` means
    the centre has crossed the plane: the sphere tunnelled. Further behind, the distance
    counts as in front (the far side of a cube is not inside its near face).
    """
    p, r, plane = pos.to(torch.float64), radius.to(torch.float64), plane.to(torch.float64)
    if kind == GROUND:
        return _half_space_depth(p, r, plane)
    return _rectangle_depth(p, r, plane, 1e-12)


def _half_space_depth(p: torch.Tensor, r: torch.Tensor, plane: torch.Tensor) -> torch.Tensor:
    """``r − (p − c)·n``, broadcast: p ``[..., 3]``, r ``[...]``, plane ``[..., 11]``."""
    return r - ((p - plane[..., 0:3]) * plane[..., 3:6]).sum(-1)


def _rectangle_depth(p: torch.Tensor, r: torch.Tensor, plane: torch.Tensor, tol: float):
    """The depth into a one-sided rectangle of :func:`plane_depth`, broadcast as
    :func:`_half_space_depth`, in the dtype of ``p``; ``tol``: how far the distance may exceed
    ``|h|`` for a centre behind the plane to count as over its footprint."""
    offset = rectangle_offset(p, plane).to(p.dtype)
    height = (offset * plane[..., 3:6]).sum(-1)
    distance = torch.linalg.vector_norm(offset, dim=-1)
    behind = (height < 0) & (height > -r) & (distance <= -height + tol)  # over the footprint
    return r + torch.where(behind, -height, -distance)


def pair_depth(pos: torch.Tensor, radius: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
    """``r_i + r_j − |p_i − p_j|`` of sphere pairs, in the dtype of ``pos`` (> 0: overlap).

    pos ``[N, 3]``, radius ``[N]``, pairs ``[2, P]`` → ``[P]``.
    """
    i, j = pairs
    return radius[i] + radius[j] - torch.linalg.vector_norm(pos[i] - pos[j], dim=-1)


def edge_plane_depth(
    pos: torch.Tensor,
    radius: torch.Tensor,
    planes: torch.Tensor,
    plane_kind: torch.Tensor,
    index: torch.Tensor,
) -> torch.Tensor:
    """:func:`plane_depth` of every (plane, sphere) edge at once, in the dtype of ``pos``.

    pos ``[N, 3]``, radius ``[N]``, planes ``[S, 11]``, plane_kind ``[S]``, index ``[2, F]``
    (row 0 plane, row 1 sphere) → ``[F]``; differentiable in ``pos``.
    """
    plane, p, r = planes[index[0]], pos[index[1]], radius[index[1]]
    ground = plane_kind[index[0]] == GROUND
    return torch.where(ground, _half_space_depth(p, r, plane), _rectangle_depth(p, r, plane, 1e-6))
