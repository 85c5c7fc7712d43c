"""Spheres may not close a gap past contact (``model.contacts.pair_floor``, opt-in): after the
pair impulses and the node decoder's own change, each pp pair of the graph is a two-sided
floor that conserves momentum.

For a pair (i, j) with unit normal ``n = (p_i − p_j)/|p_i − p_j|`` and gap
``g = |p_i − p_j| − r_i − r_j``, the frame's move may not close the gap past contact:

    (ū_i − ū_j)·n ≥ −max(g, 0)/dt.

A pair that would has the deficit ``δ`` along ``n`` shared by the reduced-mass rule,
``ū_i += m_j/(m_i + m_j)·δ·n`` and ``ū_j −= m_i/(m_i + m_j)·δ·n``, so that ``m_i Δū_i + m_j Δū_j
= 0`` for any weights; where it acted, the end velocities may not approach either
(``(v_i − v_j)·n ≥ 0``, shared the same way: an inelastic floor; the network's impulses give
the rebound wherever they already keep the pair apart). A sphere in several contacts takes
each pair's share divided by the largest contact count of the two spheres (the same for both,
so each pair stays equal and opposite), and the floor is applied ``iterations`` times (Jacobi),
each on the move the last left: a stack's corrections spread one contact per iteration.

Shapes: ``pp_index [2, E]`` in the paired layout (its first half one direction of every pair),
``mean``, ``end [N, 3]``; ``weight [E/2]`` (or None) 0 for a fixed-capacity graph's masked
candidates.
"""

from __future__ import annotations

import torch


def pair_geometry(state, pp_index: torch.Tensor):
    """``(src [P], dst [P], n [P, 3], limit [P], share_dst [P], share_src [P])`` of the graph's
    pairs: unit normals from src to dst, the least relative normal move allowed (m/s) and the
    reduced-mass shares of a relative change along ``n``."""
    half = pp_index.shape[1] // 2
    src, dst = pp_index[:, :half]
    centre = state.pos[dst] - state.pos[src]
    distance = centre.norm(dim=1)
    normal = centre / distance.clamp_min(1e-12)[:, None]
    gap = distance - state.radius[dst] - state.radius[src]
    limit = -gap.clamp_min(0) / state.scene_dt[dst]
    m_i, m_j = state.mass[dst], state.mass[src]
    return src, dst, normal, limit, m_j / (m_i + m_j), m_i / (m_i + m_j)


def pair_floor(state, pp_index, mean, end=None, weight=None, iterations: int = 4):
    """``(mean, end)`` after ``iterations`` rounds of the pairs' floor (module doc); ``end``
    None: a finite-difference state (its velocity is its move)."""
    if pp_index.shape[1] == 0:
        return mean, end
    src, dst, normal, limit, share_dst, share_src = pair_geometry(state, pp_index)
    n = mean.shape[0]
    acted = torch.zeros_like(limit)
    for _ in range(iterations):
        closing = ((mean[dst] - mean[src]) * normal).sum(1)
        deficit = torch.relu(limit - closing)
        if weight is not None:
            deficit = deficit * weight
        active = (deficit > 0).to(mean.dtype)
        acted = torch.maximum(acted, active)
        count = mean.new_zeros(n).index_add_(0, dst, active).index_add_(0, src, active)
        deficit = deficit / torch.maximum(count[dst], count[src]).clamp_min(1)
        mean = shared(mean, src, dst, normal, deficit, share_dst, share_src)
    if end is None:
        return mean, None
    approach = torch.relu(-((end[dst] - end[src]) * normal).sum(1)) * acted
    count = end.new_zeros(n).index_add_(0, dst, acted).index_add_(0, src, acted)
    approach = approach / torch.maximum(count[dst], count[src]).clamp_min(1)
    return mean, shared(end, src, dst, normal, approach, share_dst, share_src)


def shared(vel, src, dst, normal, speed, share_dst, share_src):
    """``vel [N, 3]`` with each pair's relative ``speed [P]`` along ``normal`` added, dst taking
    ``share_dst`` of it and src ``−share_src`` (momentum kept)."""
    push = speed[:, None] * normal
    vel = vel.index_add(0, dst, share_dst[:, None] * push)
    return vel.index_add(0, src, -share_src[:, None] * push)
