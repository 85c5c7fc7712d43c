"""Unit quaternions, scalar-first ``(w, x, y, z)``, in torch.

pybullet speaks ``(x, y, z, w)``: convert with :func:`from_xyzw` / :func:`to_xyzw` at that
boundary only. All functions broadcast over leading dimensions, ``[..., 4]``.
"""

from __future__ import annotations

import torch

# Below this rotation half-angle the Taylor series of sin(a)/a is used (float32-safe).
_SMALL_ANGLE = 1e-4


def from_xyzw(q: torch.Tensor) -> torch.Tensor:
    """pybullet ``(x, y, z, w)`` → physgnn ``(w, x, y, z)``. ``[..., 4]``."""
    return torch.cat([q[..., 3:4], q[..., :3]], dim=-1)


def to_xyzw(q: torch.Tensor) -> torch.Tensor:
    """physgnn ``(w, x, y, z)`` → pybullet ``(x, y, z, w)``. ``[..., 4]``."""
    return torch.cat([q[..., 1:], q[..., :1]], dim=-1)


def identity(*shape: int, dtype=torch.float32, device=None) -> torch.Tensor:
    """Identity quaternions ``[*shape, 4]``."""
    q = torch.zeros(*shape, 4, dtype=dtype, device=device)
    q[..., 0] = 1.0
    return q


def multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a ⊗ b``. ``[..., 4] × [..., 4] → [..., 4]``."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        dim=-1,
    )


def conjugate(q: torch.Tensor) -> torch.Tensor:
    """``(w, -x, -y, -z)``: the inverse of a unit quaternion. ``[..., 4]``."""
    return torch.cat([q[..., :1], -q[..., 1:]], dim=-1)  # no host-to-device copy of signs


def normalize(q: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """Scale to unit norm; a zero quaternion becomes the identity. ``[..., 4]``."""
    norm = q.norm(dim=-1, keepdim=True)
    unit = q / norm.clamp_min(eps)
    return torch.where(norm > eps, unit, identity(*q.shape[:-1], dtype=q.dtype, device=q.device))


def log(q: torch.Tensor) -> torch.Tensor:
    """Rotation vector ``θ·u`` of a unit quaternion (the doubled quaternion logarithm).

    Takes the shortest arc (``q`` and ``-q`` give the same result), is exact at the
    identity and well conditioned near a half turn (uses ``atan2`` rather than ``acos``).
    The input is normalised first. ``[..., 4] → [..., 3]``, angle in ``[0, π]``.
    """
    q = normalize(q)
    # Components below √(smallest normal) (~1e-154 in float64) are zeroed first: they change
    # the rotation by nothing measurable, but a denormal one would otherwise choose the sign
    # below, and rescaling q (which may flush it to 0) would then give the other half turn.
    q = torch.where(q.abs() < torch.finfo(q.dtype).tiny ** 0.5, torch.zeros_like(q), q)
    # Canonical sign: w > 0, or at exactly a half turn (w = 0) the first non-zero of x, y, z
    # positive, so that q and −q give the same rotation vector even there.
    w, x, y, z = q.unbind(-1)
    lead = torch.where(w != 0, w, torch.where(x != 0, x, torch.where(y != 0, y, z)))
    q = torch.where((lead < 0).unsqueeze(-1), -q, q)
    w, xyz = q[..., 0], q[..., 1:]
    s = xyz.norm(dim=-1)
    half = torch.atan2(s, w)  # in [0, π/2]
    # θ·u = 2·half·xyz/s; near 0, half/s = atan(s/w)/s = 1/w·(1 − s²/(3w²) + O(s⁴)).
    small = half < _SMALL_ANGLE
    safe_s = torch.where(small, torch.ones_like(s), s)
    w_safe = w.clamp_min(1e-12)
    taylor = 2.0 / w_safe * (1.0 - (s / w_safe) ** 2 / 3.0)
    scale = torch.where(small, taylor, 2.0 * half / safe_s)
    return xyz * scale.unsqueeze(-1)


def exp(rotvec: torch.Tensor) -> torch.Tensor:
    """Unit quaternion of a rotation vector ``θ·u``. ``[..., 3] → [..., 4]``."""
    theta = rotvec.norm(dim=-1, keepdim=True)
    half = 0.5 * theta
    small = theta < _SMALL_ANGLE
    safe_theta = torch.where(small, torch.ones_like(theta), theta)
    # sin(θ/2)/θ → 1/2 − θ²/48 near 0.
    sinc = torch.where(small, 0.5 - theta**2 / 48.0, torch.sin(half) / safe_theta)
    return torch.cat([torch.cos(half), rotvec * sinc], dim=-1)


def angular_velocity(q_prev: torch.Tensor, q_next: torch.Tensor, dt: float) -> torch.Tensor:
    """World-frame ω with ``q_next = exp(ω·dt) ⊗ q_prev``: ``log(q_next ⊗ q_prev⁻¹) / dt``.

    ``[..., 4] × [..., 4] → [..., 3]`` (rad/s).
    """
    return log(multiply(q_next, conjugate(q_prev))) / dt


def integrate(q: torch.Tensor, omega: torch.Tensor, dt: float) -> torch.Tensor:
    """One semi-implicit Euler step of the orientation (report §3.4).

    ``q ← normalise(q + ½·dt·(0, ω) ⊗ q)``, with ω in the world frame, consistent with
    :func:`angular_velocity`. ``[..., 4] × [..., 3] → [..., 4]``.
    """
    omega_q = torch.cat([torch.zeros_like(omega[..., :1]), omega], dim=-1)
    return normalize(q + 0.5 * dt * multiply(omega_q, q))


def geodesic_angle(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle of the rotation taking ``b`` to ``a``, in ``[0, π]``. ``[..., 4] → [...]``."""
    return log(multiply(a, conjugate(b))).norm(dim=-1)
