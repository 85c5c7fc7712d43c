"""Contacts within the frame: the passes of one learned step, and the contact memory that the
graph's rules also link by (``model.contacts``: :class:`~physgnn.models.options.ContactHandling`).

**Passes** (``contact_passes`` = K > 0): after a pass, the graph is built again with the pass's
provisional next velocities (spheres in reach take the network's, the others their ballistic
one; :class:`~physgnn.graph.builder.GraphBuilder`, "Contacts within the frame") and the network
passes again, while a rebuild adds edges, at most K times. A counted graph knows its size on the
host after its build, so stopping reads nothing more back; a fixed-capacity graph always makes
K passes.

**A pass costs what its new edges cost** (``incremental_passes``, on by default): a rebuild adds
a few edges (0.3–1 % on the bench's piles), so a pass after one runs the network only where the
change can reach, within M − 1 pp hops (M message-passing blocks) of the ends of the edges it
adds or lacks and of edges whose input row differs, within M hops of spheres whose input row
differs, and keeps the last pass's latents everywhere else (:mod:`physgnn.nn.changes`,
:mod:`physgnn.nn.reuse`): the same numbers up to float rounding, one more read-back (the
sizes of the changed sets). A :class:`PassMemory` carries the latents from pass to
pass. Whole passes where that cannot be: graphs padded to buckets or of fixed capacity (their
shapes are meant to stay fixed), and a ``head`` set on the instance (a compiled region,
:func:`~physgnn.models.capture.compile_simulator`; a test's oracle), which is called as it is.
The training loss's one pass is a whole pass (there is nothing to reuse); push-forward and
rollouts reuse. The path is differentiable: a kept latent is the same function of the weights
as the whole pass's, so gradients through a reused pass are the whole pass's (tested).

**Contact memory** (``contact_memory=True``, opt-in): the rules also link by the last frame's
motion reversed (``−v_t``: since ``p_t − p_{t−1} = dt·v_t``, a pair or a plane that could have
touched during the last frame), so a contact keeps its edges one frame after it parts. The
finite-difference velocity of a frame that held a bounce is the frame's mean, not the physical
velocity after the bounce; with the memory the network may correct it the frame after, where
without it the sphere is already ballistic. Unlike the latch, input noise does not trip it.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from physgnn.models.options import ContactHandling
from physgnn.models.protocol import motion_of
from physgnn.nn.reuse import Latents, again


@dataclass
class PassMemory:
    """What a pass keeps for the next pass of the same step: the network's
    :class:`~physgnn.nn.reuse.Latents` (None before the first pass)."""

    latents: Latents | None = None


def network_call(network, pairs: bool, memory: PassMemory | None):
    """``network``'s call on its inputs ``(x, pp_index, pp_attr, ps_index, ps_attr,
    material)``: ``forward_pairs`` with ``pairs``, else ``forward``; with a ``memory``, the same
    answer reusing its latents and keeping this pass's there (module doc)."""
    if memory is None:
        return network.forward_pairs if pairs else network

    def reusing(*inputs):
        out, pair_out, memory.latents = again(network, memory.latents, *inputs, pairs=pairs)
        return (out, pair_out) if pairs else out

    return reusing


def reuses(sim) -> bool:
    """True when ``sim``'s passes after a rebuild reuse the last pass's latents (module doc).
    Not in training mode: a training step's push-forward keeps whole passes, so that it makes
    no read-back beyond the training step's own (the reuse reads its set sizes once a pass)."""
    whole = sim.padded or "head" in vars(sim)  # a head set on the instance is called as it is
    on = sim.contacts.incremental_passes and sim.contacts.contact_passes > 0
    return on and not whole and not sim.training


def recalled(contacts: ContactHandling, state) -> tuple[torch.Tensor, ...]:
    """With ``contact_memory``, ``(−v_t,)`` ``[N, 3]``: the last frame's motion reversed, as a
    velocity the rules also link by (module doc); else ``()``."""
    return (-state.vel[:, 0],) if contacts.contact_memory else ()


def predict_motion(sim, state) -> tuple[tuple[torch.Tensor, ...], object]:
    """``((v_{t+1}, ω_{t+1}, ū, ω̄), graph)`` of ``sim`` (a
    :class:`~physgnn.models.learned.LearnedSimulator`): its ``head`` of the last pass and the
    graph that pass saw; passes while a rebuild on the provisional motion adds edges, at most
    ``contact_passes`` rebuilds, each after the first reusing the last one's latents where
    :func:`reuses` (module doc)."""
    provisional = list(recalled(sim.contacts, state))
    graph, basis = sim.graph_builder.build(state, provisional)
    memory = (PassMemory(),) if reuses(sim) else ()
    motion = sim.head(state, graph, tuple(provisional), *memory)
    for _ in range(int(sim.contacts.contact_passes)):
        (vel, _), mean = motion_of(motion)
        provisional.append(vel if mean is None else mean[0])
        wider, basis = sim.graph_builder.extend(state, basis, provisional)
        if not wider.grew(graph):
            break
        graph = wider
        motion = sim.head(state, graph, tuple(provisional), *memory)
    return motion, graph
