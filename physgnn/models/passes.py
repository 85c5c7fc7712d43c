"""Contacts within the frame: the passes of one learned step, and the contact memory that the
graph's rules also link by (``model.contacts``: :class:`~physgnn.models.options.ContactHandling`).

**Passes** (``contact_passes`` = K > 0): after a pass, the graph is built again with the pass's
provisional next velocities (spheres in reach take the network's, the others their ballistic
one; :class:`~physgnn.graph.builder.GraphBuilder`, "Contacts within the frame") and the network
passes again, while a rebuild adds edges, at most K times. A counted graph knows its size on the
host after its build, so stopping reads nothing more back; a fixed-capacity graph always makes
K passes.

**Contact memory** (``contact_memory=True``, opt-in): the rules also link by the last frame's
motion reversed (``−v_t``: since ``p_t − p_{t−1} = dt·v_t``, a pair or a plane that could have
touched during the last frame), so a contact keeps its edges one frame after it parts. The
finite-difference velocity of a frame that held a bounce is the frame's mean, not the physical
velocity after the bounce; with the memory the network may correct it the frame after, where
without it the sphere is already ballistic. Unlike the latch, input noise does not trip it.
"""

from __future__ import annotations

import torch

from physgnn.models.options import ContactHandling
from physgnn.models.protocol import motion_of


def recalled(contacts: ContactHandling, state) -> tuple[torch.Tensor, ...]:
    """With ``contact_memory``, ``(−v_t,)`` ``[N, 3]``: the last frame's motion reversed, as a
    velocity the rules also link by (module doc); else ``()``."""
    return (-state.vel[:, 0],) if contacts.contact_memory else ()


def predict_motion(sim, state) -> tuple[tuple[torch.Tensor, ...], object]:
    """``((v_{t+1}, ω_{t+1}, ū, ω̄), graph)`` of ``sim`` (a
    :class:`~physgnn.models.learned.LearnedSimulator`): its ``head`` of the last pass and the
    graph that pass saw; passes while a rebuild on the provisional motion adds edges, at most
    ``contact_passes`` rebuilds (module doc)."""
    provisional = list(recalled(sim.contacts, state))
    graph, basis = sim.graph_builder.build(state, provisional)
    motion = sim.head(state, graph, tuple(provisional))
    for _ in range(int(sim.contacts.contact_passes)):
        (vel, _), mean = motion_of(motion)
        provisional.append(vel if mean is None else mean[0])
        wider, basis = sim.graph_builder.extend(state, basis, provisional)
        if not wider.grew(graph):
            break
        graph = wider
        motion = sim.head(state, graph, tuple(provisional))
    return motion, graph
