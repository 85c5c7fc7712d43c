"""The connectivity rules: which sphere pairs (pp) and which (plane, sphere) pairs (ps) a graph
links, given a per-sphere motion allowance ``a_i`` and ``gap_ij = |p_i − p_j| − r_i − r_j``.

- ``approach`` (the default model's): by the pair's *relative* motion. With
  ``n̂_ij = (p_i − p_j)/|p_i − p_j|`` and the closing speed ``c_ij = max(0, −(v_i − v_j)·n̂_ij)``,
  pp edge iff ``gap_ij ≤ factor · c_ij · dt + ε`` (ε a thin shell that keeps resting contacts
  linked). Spheres moving as one (``v_i = v_j``) are never linked unless they touch: a block in
  free flight has no pp edge. Superset property: with constant relative velocity ``w`` over
  the frame, ``|d + wτ| ≥ (d + wτ)·n̂ = |d| − τ·(−w·n̂)``, so no pair can touch by ``dt`` that
  the rule leaves out (factor ≥ 1); gravity cancels in ``w`` when both spheres fly (not when
  one is supported: :mod:`physgnn.graph.rebuild`, "Contacts within the frame"). A bounded
  plane is linked when its rectangle's clearance ``|δ| − r_i ≤ factor · max(0, −v̂_i·δ̂) · dt + ε``,
  with the ballistic next velocity ``v̂_i = v_i + g·dt`` (a plane is static, so gravity does
  close the gap) and ``δ̂`` the unit offset from the rectangle's closest point (a supporting
  half-space bounds the distance alike). ``a_i = factor · |v̂_i| · dt`` sizes the search and
  the clip.
- ``epsilon``: ``a_i = 0``
- ``vmax``:    ``a_i = factor · V_max · dt``, V_max the largest speed in the sphere's scene
- ``vi``:      ``a_i = factor · |v_i| · dt``

For the last three: pp edge iff ``gap_ij ≤ a_i + a_j + ε``; ps edge to a bounded non-ground
plane iff (distance from the centre to the closest point of the rectangle) ``− r_i ≤ a_i + ε``.
Every rule: the centre is not more than ``r_i`` behind a bounded plane (planes are one-sided: a
sphere wholly behind one has tunnelled and feels nothing); plus one edge from every sphere's
ground plane. The rules are evaluated in float64 (boundary included) and read nothing back.

Effects (``state.effects``): no pp edges without ``sphere_contact``; no wall/static edges
without ``surface_contact``; the ground edge exists when ``gravity`` or ``surface_contact``.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from physgnn.data.state import scene_of_sphere
from physgnn.physics.energy import G
from physgnn.physics.geometry import rectangle_offset
from physgnn.physics.scene import EFFECT_NAMES, GROUND

CONNECTIVITIES = ("approach", "epsilon", "vmax", "vi")
GRAVITY = EFFECT_NAMES.index("gravity")
SPHERE_CONTACT = EFFECT_NAMES.index("sphere_contact")
SURFACE_CONTACT = EFFECT_NAMES.index("surface_contact")


class ConnectivityRules:
    """The rules of one ``connectivity`` (module doc); ``epsilon`` is a length in metres,
    ``factor`` scales the velocity terms."""

    def __init__(self, connectivity: str, epsilon: float, factor: float):
        if connectivity not in CONNECTIVITIES:
            raise ValueError(
                f"unknown connectivity '{connectivity}'; choose one of {list(CONNECTIVITIES)}"
            )
        for name, value in (("epsilon", epsilon), ("factor", factor)):
            check_length(name, value)
        self.connectivity = connectivity
        self.epsilon = float(epsilon)
        self.factor = float(factor)

    def rules(
        self, state, velocity, allowance, src, dst, plane, sphere, pair_velocity=None
    ) -> tuple:
        """``(pp mask [P], ps mask [Q], offsets [Q, 3] float64)`` of the candidates: the module
        doc's rules, given :meth:`rule_velocity` (or a pass's provisional velocity) and
        :meth:`allowance`; ``pair_velocity [N, 3]``: what the pp rule moves spheres with
        (None: ``v_t``). Reads nothing back: a compiled simulator compiles it
        (:mod:`physgnn.models.capture`)."""
        batch = scene_of_sphere(state)
        on = state.effects[batch[src], SPHERE_CONTACT]  # scenes with sphere contact
        pp_mask = on & self.pair_within_reach(state, src, dst, allowance, pair_velocity)
        ps_mask, offset = self._ps_rule(state, batch, allowance, plane, sphere, velocity)
        return pp_mask, ps_mask, offset

    def rule_velocity(self, state) -> torch.Tensor:
        """``[N, 3]``: what the rules move spheres with: ``v_t + g·dt`` (approach), else ``v_t``."""
        if self.connectivity == "approach":
            return ballistic_velocity(state)
        return current_velocity(state)

    def allowance(self, state, moving=None, velocity=None) -> torch.Tensor:
        """Motion allowance ``a_i`` of every sphere, float64 ``[N]``; ``moving [N]`` (bool):
        only these spheres move, the others count with speed 0 (sleeping spheres);
        ``velocity [N, 3]``: :meth:`rule_velocity` where the caller has it."""
        batch = scene_of_sphere(state)
        vel = self.rule_velocity(state) if velocity is None else velocity
        speed = vel.to(torch.float64).norm(dim=-1)
        if self.connectivity == "epsilon":
            return torch.zeros_like(speed)
        if moving is not None:
            speed = torch.where(moving, speed, 0.0)
        if self.connectivity == "vmax":
            vmax = speed.new_zeros(state.dt.shape[0]).scatter_reduce(0, batch, speed, "amax")
            speed = vmax[batch]
        return self.factor * speed * state.dt.to(torch.float64)[batch]

    def reach(self, state, allowance: torch.Tensor) -> torch.Tensor:
        """``ρ_i = r_i + a_i + ε``, float64 ``[N]``: the farthest plane a sphere may touch."""
        return state.radius.to(torch.float64) + allowance + self.epsilon

    def pair_within_reach(self, state, i, j, allowance: torch.Tensor, velocity=None):
        """``[P]`` bool: the pp rule (module doc; ``gap_ij ≤ a_i + a_j + ε`` but for
        ``approach``) of same-scene pairs ``(i, j)``, float64; ``approach`` moves the spheres
        with ``velocity [N, 3]`` (None: ``v_t``; a common gravity cancels in the pair)."""
        batch = scene_of_sphere(state)
        p, r = state.pos.to(torch.float64), state.radius.to(torch.float64)
        rel = p[i] - p[j]
        dist = rel.norm(dim=-1)
        gap = dist - r[i] - r[j]
        if self.connectivity == "approach":
            vel = (current_velocity(state) if velocity is None else velocity).to(torch.float64)
            along = ((vel[i] - vel[j]) * rel).sum(-1) / dist.clamp_min(1e-300)
            limit = self._closing_limit(along, state.dt.to(torch.float64)[batch[i]])
        else:
            limit = allowance[i] + allowance[j] + self.epsilon
        return (batch[i] == batch[j]) & (gap <= limit)

    def plane_within_reach(
        self, state, sphere, normal, clearance, allowance, velocity=None, fall=None
    ) -> torch.Tensor:
        """``[Q]`` bool: a plane at ``clearance [Q]`` (float64, from the sphere's surface along
        the unit direction ``normal [Q, 3]`` pointing from the plane to the sphere) can be
        reached by ``sphere [Q]`` before the next frame: ``approach``'s
        ``clearance ≤ factor · max(0, −v̂·n) · dt + ε``, else ``clearance ≤ a_i + ε`` (plus
        ``fall [Q]`` where given: :meth:`touches_plane`); ``velocity [N, 3]``:
        :meth:`rule_velocity` where the caller has it."""
        if self.connectivity != "approach":
            limit = allowance[sphere] + self.epsilon
            return clearance <= (limit if fall is None else limit + fall)
        vel = self.rule_velocity(state) if velocity is None else velocity
        vel = vel.to(torch.float64)[sphere]
        along = (vel * normal.to(torch.float64)).sum(-1)
        dt = state.dt.to(torch.float64)[scene_of_sphere(state)[sphere]]
        return clearance <= self._closing_limit(along, dt)

    def touches_plane(
        self, state, sphere, normal, clearance, allowance, provisional: Sequence = ()
    ) -> torch.Tensor:
        """``[Q]`` bool: :meth:`plane_within_reach` counting gravity's fall within the frame,
        under the rule's own motion or any ``provisional`` velocity (the union, as a build
        keeps edges): ``approach`` moves spheres by ``v̂ = v + g·dt``, which counts the fall,
        and reads each velocity; the other rules add the fall ``g·dt²`` to ``a_i + ε`` (their
        allowance already holds the provisional velocities). The gravity prior's plane reach
        (:mod:`physgnn.models.reach`)."""
        args = state, sphere, normal, clearance, allowance
        if self.connectivity != "approach":
            dt = state.scene_dt[sphere]
            return self.plane_within_reach(*args, fall=G * dt * dt)
        near = self.plane_within_reach(*args)
        for vel in provisional:
            near = near | self.plane_within_reach(*args, vel)
        return near

    def _closing_limit(self, along: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
        """``approach``'s limit ``factor · max(0, −along) · dt + ε`` of a gap or clearance, with
        ``along`` the velocity along the direction from the contact to the sphere (float64)."""
        return self.factor * torch.relu(-along) * dt + self.epsilon

    def _ps_rule(self, state, batch, allowance, plane, sphere, vel) -> tuple[torch.Tensor, ...]:
        """``([Q] bool, offsets [Q, 3] float64)`` for (plane, sphere) candidates of one scene
        (the offsets from each rectangle, kept for the edge features): the ground of a scene with
        gravity or surface contact; a wall or static plane of a scene with surface contact
        whose rectangle is in reach (:meth:`plane_within_reach` with ``vel``, the rule's
        velocity) and which the centre is not more than ``r_i`` behind (planes are one-sided)."""
        effects = state.effects[batch[sphere]]
        ground = state.plane_kind[plane] == GROUND
        offset = rectangle_offset(state.pos[sphere], state.planes[plane])
        radius = state.radius.to(torch.float64)[sphere]
        height = (offset * state.planes[plane, 3:6].to(torch.float64)).sum(-1)
        dist = offset.norm(dim=-1, keepdim=True)
        direction = offset / dist.clamp_min(1e-300)
        clearance = dist[:, 0] - radius
        near = self.plane_within_reach(state, sphere, direction, clearance, allowance, vel)
        bounded = ~ground & effects[:, SURFACE_CONTACT] & near & (height > -radius)
        keep = (ground & (effects[:, GRAVITY] | effects[:, SURFACE_CONTACT])) | bounded
        return keep, offset


def check_length(name: str, value) -> None:
    """A length or factor of the rules is finite and >= 0, else ``ValueError`` naming it."""
    if not 0 <= float(value) < float("inf"):
        raise ValueError(f"{name} must be finite and >= 0, got {value}")


def ballistic_velocity(state) -> torch.Tensor:
    """``v_t + g·dt`` ``[N, 3]``: the next velocity in free flight (g only in scenes with
    gravity)."""
    gravity = state.effects[scene_of_sphere(state), GRAVITY].to(state.pos.dtype)
    vel = current_velocity(state).clone()
    vel[:, 2] = vel[:, 2] - G * state.scene_dt * gravity
    return vel


def current_velocity(state) -> torch.Tensor:
    """Current velocity ``v_t``, ``[N, 3]`` (``vel`` is ``[N, H+1, 3]``, latest first)."""
    return state.vel[:, 0] if state.vel.dim() == 3 else state.vel
