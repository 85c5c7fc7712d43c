"""Contacts within the frame: a build under provisional velocities, and its incremental rebuild.

The superset property of the rules (:mod:`physgnn.graph.rules`) holds under their own
assumption, each sphere moving with its ballistic velocity for the whole frame. It fails when a
sphere's motion changes within the frame: a neighbour stopped by the ground (a block's bottom
layer lands, a ball hits a resting row) or a sphere that rests while a falling one comes down on
it (gravity does not cancel in that pair). So a build also takes the provisional next
velocities of earlier passes of a simulator (``provisional``): a candidate is kept when the rules
accept it under the ballistic motion *or* under any provisional one (the union, so a graph only
grows from pass to pass), and the allowance is the largest of them. Under each velocity the
superset property holds as above (tested against brute force); a simulator passes again while
a rebuild adds edges (:class:`~physgnn.models.learned.LearnedSimulator`, ``contact_passes``).

A rebuild with one more velocity (:meth:`~physgnn.graph.builder.GraphBuilder.extend`) reuses
the last build's :class:`Basis` where that velocity widens no allowance (:func:`widened`; on
the CPU: 1.11–1.14× faster frames of the default model, the same graph edge for edge); where it
widens some, it searches pairs for the grown spheres only (:func:`grown_pairs`) and judges the
candidates anew: a frame makes one whole build.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from physgnn.graph.neighbors import BallIndex, exact_pairs, extent_span
from physgnn.graph.rules import ConnectivityRules


@dataclass(frozen=True)
class Basis:
    """What a build compacts its graph from: the allowance ``[N]`` (float64), the candidates
    ``(src [P], dst [P], plane [Q], sphere [Q])``, the rules' masks ``([P], [Q])`` under every
    velocity so far, the ps offsets ``[Q, 3]`` and whether the pp candidates are the layout's
    (:meth:`~physgnn.graph.builder.GraphBuilder.layout_candidates`)."""

    allowance: torch.Tensor
    candidates: tuple[torch.Tensor, ...]
    masks: tuple[torch.Tensor, torch.Tensor]
    offset: torch.Tensor
    layout: bool


def union_allowance(
    rules: ConnectivityRules, state, velocity: torch.Tensor, provisional: Sequence[torch.Tensor]
) -> torch.Tensor:
    """``[N]`` float64: the largest allowance under the rule's ``velocity [N, 3]`` and every
    provisional velocity ``[N, 3]``."""
    allowance = rules.allowance(state, velocity=velocity)
    for vel in provisional:
        allowance = torch.maximum(allowance, rules.allowance(state, velocity=vel))
    return allowance


def union_masks(
    rules: ConnectivityRules, state, velocity, allowance, candidates, provisional: Sequence
) -> tuple[torch.Tensor, ...]:
    """``(pp mask [P], ps mask [Q], offsets [Q, 3])`` of ``candidates`` ``(src, dst, plane,
    sphere)``: the rules' masks under the rule's ``velocity`` or any provisional one (the
    union)."""
    pp_mask, ps_mask, offset = rules.rules(state, velocity, allowance, *candidates)
    for vel in provisional:
        more = rules.rules(state, vel, allowance, *candidates, vel)
        pp_mask, ps_mask = pp_mask | more[0], ps_mask | more[1]
    return pp_mask, ps_mask, offset


def widened(rules: ConnectivityRules, state, basis: Basis, velocity) -> Basis | None:
    """``basis`` with the masks of one more provisional ``velocity [N, 3]`` added, or None
    where that velocity widens an allowance (other candidates: :func:`grown_pairs`)."""
    allowance = torch.maximum(basis.allowance, rules.allowance(state, velocity=velocity))
    if not torch.equal(allowance, basis.allowance):
        return None
    pp_mask, ps_mask, _ = rules.rules(state, velocity, allowance, *basis.candidates, velocity)
    masks = (basis.masks[0] | pp_mask, basis.masks[1] | ps_mask)
    return dataclasses.replace(basis, masks=masks)


def grown_pairs(state, batch, grown: torch.Tensor, reach: float, pairs: tuple) -> tuple:
    """``(src, dst)``: the candidate ``pairs`` (``i < j``, sorted) with every same-scene pair
    within ``reach`` (m) of a sphere of ``grown [G]`` (indices) added, sorted the same way: the
    radius search of a whole build, asked of the grown spheres only (CPU k-d tree)."""
    pos, n = state.pos, state.pos.shape[0]
    span = extent_span(pos, 2.0 * reach)
    search = torch.full((grown.shape[0],), reach, dtype=torch.float64)
    rows, cols = BallIndex(pos, batch, span).near(pos[grown], batch[grown], search)
    found = exact_pairs(pos, batch, reach, grown[rows], cols)
    key = torch.unique(torch.cat([pairs[0] * n + pairs[1], found[0] * n + found[1]]))
    return key // n, key % n
