"""The energy guard (``model.contacts.energy_guard``): a rollout frame's contacts never raise
the energy of a group of spheres in contact beyond what parts its overlaps.

Contacts with restitution ≤ 1 and Coulomb friction only take energy out of a frame. The truth
agrees: over the small preset's train, val and test frames a scene's energy
``E = Σ ½m|v|² + ½I|ω|² + m·g·z`` rises by at most 0.13 mm of its weight ``Σ m·g`` in a frame,
0.9 mm on the OOD split (the engine pushing overlaps apart). A network that extrapolates can
answer a dense impact with more energy than came in, and the next frame with more still: a
200-sphere pile, ten times the training scenes', ran away from 20 to 7 700 m/s in 8 frames.

The guard takes the frame's contact changes ``Δ = x − x_free`` of every sphere the network
moves (``x`` its end velocities and mean move, ``x_free`` free flight), and scales them in each
contact group (the spheres the graph's pp edges link, :func:`contact_groups`; no momentum passes
between two groups) by one factor ``α ∈ [0, 1]``, the largest with

    E(α) ≤ E_t + allowance,   E(α) = Σ ½m|v_free + α Δv|² + ½I|ω_free + α Δω|²
                                     + m·g·dt·(ū_free + α Δū)_z   (a quadratic in α),

summed over the group, ``E_t`` its energy at the frame's start (potential energy measured from
``z_t``). Free flight (``α = 0``) never gains energy (the integrator's share ``s ≥ ½`` of
``g·dt``), so such an ``α`` exists; it is 1, the network's own answer, wherever the frame
creates no energy. One factor per group keeps every pair impulse equal and opposite: momentum
stays exact; a group neither pays for another's energy nor hides it (a sphere rolling on the
ground is a group of its own). Spheres the rest decision stops keep ``v = ω = 0`` (their energy
counted as it is); the planes' floor then holds the move out of the planes once more
(:func:`~physgnn.models.motion.floored_move`).

The allowance: the energy that parts the overlaps the frame starts with within the frame
(:func:`parting_energy`; the engine pushes overlaps apart too), plus ``slack·Σ m·g``, 0 by
default: an allowance that every frame grants whatever the scene is spent by the network (at
1 mm a sphere of ``tight_pack`` rolled away at up to 10 m/s). Without overlaps a rollout's
energy after T frames is at most ``E_0 + T·slack·Σ m·g``: it cannot run away, whatever the
weights. It is not a law for the training loss (``sim.training``): the network learns from its
own answer, not from one the guard has cut.
"""

from __future__ import annotations

import torch

from physgnn.data.state import scene_of_sphere
from physgnn.graph.rules import GRAVITY
from physgnn.models.floor import contact_directions
from physgnn.physics.energy import G

# rounds of min-label propagation, each with pointer jumping; a scene whose groups they do not
# settle takes one factor (exact all the same)
ROUNDS = 8
# m: the deepest overlap whose parting a frame may pay for. The engine's own stay below it (at
# most 1.8 mm in a resting pile of 200 spheres); deeper ones are a network's error, and paying
# to part them in one frame let a dense pile pump energy (0.5 m: 5 m/s of parting speed).
PARTED = 0.01


def guarded(
    state,
    free: tuple,
    moves: tuple,
    fixed: torch.Tensor | None,
    slack: float,
    graph=None,
    contacts: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> tuple:
    """``moves`` ``(v, ω, ū, ω̄)`` ``[N, 3]`` each, after the guard (module doc).

    ``free``: the same four in free flight; ``fixed [N]`` bool (None: none): spheres whose
    moves stay as they are (those the rest decision stopped); ``slack`` (m): the energy a
    frame may add, as a height of the weight; ``graph``: the step's, whose contact groups each
    take their own factor and whose overlaps may be parted (:func:`contact_groups`,
    :func:`parting_energy`; None: one factor per scene, no overlap); ``contacts``: its ps
    edges' :func:`~physgnn.models.floor.contact_directions`, where the caller has them."""
    delta = [m - f for m, f in zip(moves, free, strict=True)]
    base = list(free)
    if fixed is not None:
        keep = fixed[:, None]
        base = [torch.where(keep, m, f) for m, f in zip(moves, free, strict=True)]
        delta = [torch.where(keep, torch.zeros_like(d), d) for d in delta]
    scene = scene_of_sphere(state)
    scenes = state.num_graphs if hasattr(state, "num_graphs") else 1
    parting, group, groups = None, scene, scenes
    if graph is not None:
        parting = parting_energy(state, graph, contacts)
        group, whole = contact_groups(graph, scene, scenes)
        # a scene whose groups the rounds did not settle is one group (ids after the spheres')
        n = scene.shape[0]
        group, groups = torch.where(whole[scene], group, n + scene), n + scenes
    terms = energy_terms(state, base, delta, slack, parting)
    alpha = factor(terms, group, groups)[group]
    return tuple(b + alpha[:, None] * d for b, d in zip(base, delta, strict=True))


def contact_groups(graph, scene: torch.Tensor, scenes: int, rounds: int = ROUNDS) -> tuple:
    """``(group [N], whole [B])``: each sphere's contact group, the smallest sphere index it
    is linked to through the graph's pp edges (``rounds`` of min-label propagation, each with
    pointer jumping, no read-back), and per scene whether every group of it is whole (no edge
    still joins two labels; where one does, the scene takes one factor, so that each pair's
    impulses are scaled alike all the same)."""
    src, dst = graph.pp_index
    weight = graph.pp_weight(graph.pp_attr)
    if weight is not None:  # a fixed-capacity graph's masked candidates link nothing
        src = torch.where(weight > 0, src, dst)
    label = torch.arange(scene.shape[0], device=scene.device)
    for _ in range(rounds):
        label = label.scatter_reduce(0, dst, label[src], "amin")
        label = label[label]
    split = (label[src] != label[dst]).to(torch.long)
    apart = torch.zeros(scenes, dtype=torch.long, device=scene.device)
    apart = apart.index_add_(0, scene[dst], split)
    return label, apart == 0


def parting_energy(state, graph, contacts=None) -> torch.Tensor:
    """``[N]`` (J): the kinetic energy that parts every overlap of ``graph`` in one frame,
    ``½·μ·(o/dt)²`` for a pp pair overlapping by ``o`` (``μ`` the reduced mass; on its target
    sphere) and ``½·m·(o/dt)²`` for a sphere ``o`` inside a plane (``contacts``: the ps edges'
    :func:`~physgnn.models.floor.contact_directions`, None: taken here)."""
    mass, radius, pos, dt = state.mass, state.radius, state.pos, state.scene_dt
    half = graph.pp_index.shape[1] // 2
    src, dst = graph.pp_index[:, :half]
    gap = (pos[dst] - pos[src]).norm(dim=1) - radius[dst] - radius[src]
    reduced = mass[dst] * mass[src] / (mass[dst] + mass[src])
    pairs = 0.5 * reduced * (torch.relu(-gap).clamp_max(PARTED) / dt[dst]).square()
    weight = graph.pp_weight(pairs)
    pairs = pairs if weight is None else pairs * weight[:half]
    sphere = graph.ps_index[1]
    clearance = (contacts or contact_directions(graph, radius))[1]
    inside = torch.relu(-clearance).clamp_max(PARTED)
    planes = 0.5 * mass[sphere] * (inside / dt[sphere]).square()
    weight = graph.ps_weight(planes)
    planes = planes if weight is None else planes * weight
    energy = torch.zeros_like(mass).index_add_(0, dst, pairs)
    return energy.index_add_(0, sphere, planes)


def energy_terms(state, base: list, delta: list, slack: float, parting=None) -> tuple:
    """``(room, linear, square)`` ``[N]`` each: every sphere's share of ``D``, ``B`` and ``C``
    of ``E(α) = E_t + allowance − D + B·α + C·α²`` (J), the moves ``base + α·delta`` (lists
    ``[v, ω, ū, ω̄]`` of ``[N, 3]``); the allowance ``slack·m·g`` plus ``parting [N]`` (J)
    where given."""
    mass, inertia = state.mass, 0.4 * state.mass * state.radius.square()
    lift = mass * G * state.effects[scene_of_sphere(state), GRAVITY].to(mass.dtype)
    lift = lift * state.scene_dt

    def dot(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return (a * b).sum(1)

    (v, w, u, _), (dv, dw, du, _) = base, delta
    vel_t, ang_t = state.vel[:, 0], state.angvel[:, 0]
    now = 0.5 * (mass * dot(vel_t, vel_t) + inertia * dot(ang_t, ang_t))
    start = 0.5 * (mass * dot(v, v) + inertia * dot(w, w)) + lift * u[:, 2]
    allowance = slack * mass * G if parting is None else slack * mass * G + parting
    linear = mass * dot(v, dv) + inertia * dot(w, dw) + lift * du[:, 2]
    square = 0.5 * (mass * dot(dv, dv) + inertia * dot(dw, dw))
    return now - start + allowance, linear, square


def factor(terms: tuple, group: torch.Tensor, groups: int) -> torch.Tensor:
    """``[groups]``: each group's largest ``α ∈ [0, 1]`` with ``B·α + C·α² ≤ D``, the sums
    of :func:`energy_terms` over its spheres ``group [N]`` (ids below ``groups``)."""
    room, linear, square = (t.new_zeros(groups).index_add_(0, group, t) for t in terms)
    room = room.clamp_min(0.0)
    # the root of C·α² + B·α − D in the form that keeps its precision for small C
    root = 2 * room / (linear + (linear.square() + 4 * square * room).sqrt()).clamp_min(1e-30)
    return torch.where(square + linear <= room, torch.ones_like(root), root.clamp(0.0, 1.0))
