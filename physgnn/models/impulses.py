"""Pair impulses: sphere–sphere interactions decoded as equal and opposite impulses, so that
linear and angular momentum are conserved exactly, for any network weights.

For a pp pair (i target, j source, ``n = p_i − p_j``, ``s = r_i + r_j``) the network's
antisymmetric pair output ``f_ij = −f_ji`` (:class:`~physgnn.nn.pair_decoder.PairDecoder`,
6 numbers, normalised) becomes

- the impulse on i, ``P_ij = μ_ij · σ_v · f_ij[:3]`` with the reduced mass
  ``μ_ij = m_i m_j / (m_i + m_j)`` (kg·m/s), and ``−P_ij`` on j;
- applied at the contact point ``c_ij = p_i − (r_i/s)·n`` (where the surfaces meet for
  touching spheres), i.e. the torques ``(c − p_i) × P = −(r_i/s)·n × P`` on i and
  ``(c − p_j) × (−P) = −(r_j/s)·n × P`` on j;
- and a couple ``C_ij = μ^I_ij · σ_ω · f_ij[3:]`` on i, ``−C_ij`` on j (rolling and spinning
  friction), ``μ^I`` the reduced moment of inertia, ``I = 2/5 · m r²`` (solid spheres, as
  pybullet's).

So ``Δv_i = Σ_j P_ij / m_i`` and ``Δω_i = Σ_j ((c_ij − p_i) × P_ij + C_ij) / I_i``, and over
the pair ``m_i Δv_i + m_j Δv_j = 0`` and
``p_i × m_i Δv_i + I_i Δω_i + p_j × m_j Δv_j + I_j Δω_j = n × P − (r_i + r_j)/s · n × P = 0``.
A sphere's change depends on masses only through ``m_j / (m_i + m_j)`` (mass-scale invariant).
σ_v, σ_ω are the simulator's velocity-change scales (m/s, rad/s).
"""

from __future__ import annotations

import torch

from physgnn.graph.rules import ballistic_velocity
from physgnn.models.floor import contact_directions, plane_floor, pressed
from physgnn.models.friction import friction_cone, sphere_friction
from physgnn.models.outputs import PAIR, regression
from physgnn.models.pair_floor import pair_floor
from physgnn.models.pair_newton import pair_bounces

INERTIA_FACTOR = 0.4  # I = 2/5 m r² of a solid sphere


def sphere_inertia(mass: torch.Tensor, radius: torch.Tensor) -> torch.Tensor:
    """``[N]``: ``2/5 · m r²`` (kg·m²)."""
    return INERTIA_FACTOR * mass * radius.square()


def pair_changes(state, pp_index, pair_out, speed_scale, spin_scale, weight=None):
    """``(Δv [N, 3], Δω [N, 3])`` of every sphere from the pair outputs (module doc).

    ``pp_index [2, E]`` in the paired layout; ``pair_out [E/2, 6]`` (the blocks of
    :data:`~physgnn.models.outputs.PAIR`), row e the output for
    target ``pp_index[1, e]``; ``weight [E/2]`` (or None) multiplies each pair (0 for the
    masked candidates of a fixed-capacity graph); ``speed_scale``, ``spin_scale``: σ_v, σ_ω."""
    half = pp_index.shape[1] // 2
    src, dst = pp_index[:, :half]
    mass, radius, pos = state.mass, state.radius, state.pos
    f = pair_out if weight is None else pair_out * weight[:, None]
    m_i, m_j = mass[dst], mass[src]
    impulse = (m_i * m_j / (m_i + m_j))[:, None] * speed_scale * PAIR.take(f, "impulse")
    inertia = sphere_inertia(mass, radius)
    i_i, i_j = inertia[dst], inertia[src]
    couple = (i_i * i_j / (i_i + i_j))[:, None] * spin_scale * PAIR.take(f, "couple")
    centre = pos[dst] - pos[src]
    share = (radius[dst] / (radius[dst] + radius[src]))[:, None]
    lever = torch.linalg.cross(centre, impulse)
    torque_i = -share * lever + couple
    torque_j = -(1 - share) * lever - couple
    n = pos.shape[0]
    momentum = pos.new_zeros(n, 3).index_add_(0, dst, impulse).index_add_(0, src, -impulse)
    spin = pos.new_zeros(n, 3).index_add_(0, dst, torque_i).index_add_(0, src, torque_j)
    return momentum / mass[:, None], spin / inertia[:, None]


def normalised_changes(sim, state, graph, node_out, pair_out, on_plane) -> torch.Tensor:
    """``[N, sim.outputs.width]``: the normalised velocity changes of the
    :class:`LearnedSimulator` ``sim`` (its statistics) from the network's ``node_out [N,
    sim.outputs.width]`` and ``pair_out [E'/2, sim.pair_outputs.width]`` (the graph's pairs
    first; padding after): the pair impulses (:func:`pair_changes`), gravity, and the node
    decoder's own change for spheres ``on_plane [N]`` only (with ``plane_floor``, after the
    planes' floor: :mod:`physgnn.models.floor`); with ``pair_newton`` (the engine state) the
    closed-form meetings of pairs away from the planes added to the pair impulses
    (:mod:`physgnn.models.pair_newton`); then the rest logit as it is. With
    the engine state the frame's mean motion likewise, from its own pair impulses and the
    engine's share of gravity (``sim.gravity_share``): over an isolated group,
    ``Σ m Δp = M·(dt·v̄ + s·g·dt²)`` for any weights."""
    half = graph.pp_index.shape[1] // 2
    weight = graph.pp_weight(pair_out)
    weight = None if weight is None else weight[:half]
    scales = sim.delta_speed_scale, sim.delta_spin_scale
    own = on_plane[:, None].to(node_out.dtype)
    fall = ballistic_velocity(state) - state.vel[:, 0]  # g·dt where gravity is on
    outputs, pairs = sim.outputs, sim.pair_outputs
    motions = [("", 1.0)] + ([("mean_", sim.gravity_share)] if sim.inputs.engine_state else [])
    changes = []
    for prefix, share in motions:
        columns = slice(pairs.slice(prefix + "impulse").start, pairs.slice(prefix + "couple").stop)
        dvel, dang = pair_changes(state, graph.pp_index, pair_out[:half, columns], *scales, weight)
        changes.append([dvel + share * fall, dang])
    if sim.contacts.pair_newton and sim.inputs.engine_state:  # pairs meeting in free flight
        bounces = pair_bounces(state, graph.pp_index, ~on_plane, weight)
        for change, bounce in zip(changes, bounces, strict=True):
            change[0] = change[0] + bounce
    newton = sim.contacts.plane_floor and sim.contacts.plane_newton
    # the ps edges' contact directions and clearances, once for every floor of the pass
    contacts = contact_directions(graph, state.radius) if sim.contacts.plane_floor else None
    if newton:  # the node decoder's own change only where a plane touches the sphere
        vel = state.vel[:, 0]
        own = own * pressed(state, graph, vel + changes[-1][0], contacts)[:, None].to(own.dtype)
    before = [change[0] for change in changes]
    if sim.contacts.plane_floor:
        floored(state, graph, changes, sim.contacts.plane_newton, contacts)
    add_own(sim, state, graph, node_out, own, changes, before)
    if sim.contacts.pair_floor:
        pairs_floored(state, graph, changes, weight)
    if newton:  # the move: it may not cross a plane either
        vel = state.vel[:, 0]
        changes[-1][0] = plane_floor(state, graph, vel + changes[-1][0], contacts=contacts)[0] - vel
    parts = []
    for dvel, dang in changes:
        parts.append((dvel - sim.delta_vel_mean) / sim.delta_vel_std)
        parts.append((dang - sim.delta_angvel_mean) / sim.delta_angvel_std)
    rest = node_out[:, regression(outputs).width :]
    return torch.cat(parts + [rest], 1)


def add_own(sim, state, graph, node_out, own, changes: list, before: list) -> None:
    """``changes`` plus the node decoder's own change of every motion, where ``own [N, 1]``,
    in place; with ``friction_cone``, outside training, its part along a plane within
    Coulomb's cone of the plane's push (the floor's change since ``before``;
    :mod:`physgnn.models.friction`)."""
    outputs, motions = sim.outputs, ("", "mean_")[: len(changes)]
    cone = sim.contacts.friction_cone and not sim.training
    mu = sphere_friction(state, graph) if cone else None
    for prefix, change, start in zip(motions, changes, before, strict=True):
        own_vel = outputs.take(node_out, f"delta_{prefix}vel") * sim.delta_vel_std
        own_ang = outputs.take(node_out, f"delta_{prefix}angvel") * sim.delta_angvel_std
        if cone:
            own_vel, own_ang = friction_cone(change[0] - start, own_vel, own_ang, mu)
        change[0], change[1] = change[0] + own * own_vel, change[1] + own * own_ang


def start_from_the_law(sim) -> None:
    """With ``plane_newton``: the node decoder's own changes start at zero (the rows of its
    last layer that give them), so that training starts from the planes' closed form and
    learns only what it misses; the pair outputs keep their random start."""
    last = [m for m in sim.network.decoder.modules() if isinstance(m, torch.nn.Linear)][-1]
    motions = ("", "mean_") if sim.inputs.engine_state else ("",)
    with torch.no_grad():
        for prefix in motions:
            for name in (f"delta_{prefix}vel", f"delta_{prefix}angvel"):
                rows = sim.outputs.slice(name)
                last.weight[rows] = 0.0
                last.bias[rows] = 0.0


def pairs_floored(state, graph, changes: list, weight=None) -> None:
    """``changes`` (as :func:`floored`'s) after the pairs' floor
    (:func:`~physgnn.models.pair_floor.pair_floor`: no pair closes its gap past contact in the
    move, momentum kept), in place."""
    _through(state, changes, lambda mean, end: pair_floor(state, graph.pp_index, mean, end, weight))


def floored(state, graph, changes: list, bounce: bool = False, contacts=None) -> None:
    """``changes`` (``[[Δv, Δω]]`` of the end velocity, then of the mean move with the engine
    state) after the planes' floor (:func:`~physgnn.models.floor.plane_floor`; ``bounce``: with
    the closed-form rebound of a sphere arriving in free flight), in place."""
    _through(
        state, changes, lambda mean, end: plane_floor(state, graph, mean, end, bounce, contacts)
    )


def _through(state, changes: list, floor) -> None:
    """``changes`` after ``floor(mean [N, 3], end [N, 3] | None) -> (mean, end)``, in place: a
    finite-difference state (one change) passes its velocity as the move and no end."""
    vel = state.vel[:, 0]
    if len(changes) == 1:  # a finite-difference state: its velocity is its move
        changes[0][0] = floor(vel + changes[0][0], None)[0] - vel
        return
    mean, end = floor(vel + changes[1][0], vel + changes[0][0])
    changes[0][0], changes[1][0] = end - vel, mean - vel
