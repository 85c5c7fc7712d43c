"""What training does for contacts: a hinge penalty on the predicted overlaps, and noise aimed
at contacts.

**Contact penalty.** The next positions ``p̂ = p_t + dt·v̂_{t+1}`` of a prediction must not
overlap: on the prediction's own graph (each pp pair once, every ps edge) with the depths
``d`` of :func:`~physgnn.physics.geometry.pair_depth` and
:func:`~physgnn.physics.geometry.edge_plane_depth`,

``penalty = Σ_edges (max(d − tol, 0) / (dt · σ_Δv))² / N``

``σ_Δv`` the RMS of the training set's ``delta_vel`` std: a depth is counted as the velocity
error, in the units of the normalised loss, that would have made it in one frame, so the term
is on the scale of the MSE. ``tol`` (a length) lets the ground truth's own contacts through
(pybullet's deepest overlap on the small preset is about 0.02 d, its mean 2e-4 d): the term
then penalises what the truth does not do and does not fight the data.

**Contact noise.** Rollouts reach states in which spheres sit 0.1–0.7 d inside each other or
inside a plane; input noise of 0.01 d never shows the model such a state. Each contact of the
(noisy) input, a pp pair or a ps edge with a gap below ``touch`` (a length), is pushed in with
probability ``prob`` by ``u ~ U(0, depth)``: a pair's spheres each move ``u/2`` towards each
other along their centre line, a sphere ``u`` into a plane along its normal. Velocities are
kept (a rollout sinks slowly: a deep overlap at almost no speed), and the velocity target is
moved by ``−δ/dt`` so that it brings the sphere back onto the truth, as the input noise does.
"""

from __future__ import annotations

import torch

from physgnn.physics.geometry import edge_plane_depth, pair_depth


def contact_penalty(state, vel_next: torch.Tensor, graph, tol: float, speed_scale) -> torch.Tensor:
    """The module doc's penalty (a scalar) of the prediction ``vel_next [N, 3]`` made on
    ``graph``; ``speed_scale`` is σ_Δv (m/s)."""
    n = state.pos.shape[0]
    if n == 0:
        return state.pos.new_zeros(())
    dt = state.scene_dt
    pos_next = state.pos + dt[:, None] * vel_next
    pairs = graph.pp_index[:, : graph.pp_index.shape[1] // 2]
    pp = pair_depth(pos_next, state.radius, pairs)
    ps = edge_plane_depth(pos_next, state.radius, state.planes, state.plane_kind, graph.ps_index)
    excess = torch.cat(
        [torch.relu(pp - tol) / dt[pairs[1]], torch.relu(ps - tol) / dt[graph.ps_index[1]]]
    )
    if graph.masked:  # a fixed-capacity graph: only the edges its rules accept count
        half = pairs.shape[1]
        excess = excess * torch.cat([graph.pp_weight(excess)[:half], graph.ps_weight(excess)])
    return (excess / speed_scale).square().sum() / n


def perturb_contacts(state, graph, depth, touch, prob: float, generator=None):
    """A copy of ``state`` with the contacts of ``graph`` (built on ``state``) pushed in, and
    the matching velocity targets (module doc). ``depth``, ``touch``: lengths in metres
    (floats or 0-d tensors)."""
    pos, radius = state.pos, state.radius
    n = pos.shape[0]

    def draw(count: int) -> torch.Tensor:
        """``[count]`` push depths: ``U(0, depth)`` with probability ``prob``, else 0."""
        u = torch.rand(2, count, generator=generator, dtype=pos.dtype, device=pos.device)
        return torch.where(u[0] < prob, u[1] * depth, torch.zeros_like(u[1]))

    shift = pos.new_zeros(n, 3)
    src, dst = graph.pp_index[:, : graph.pp_index.shape[1] // 2]
    rel = pos[dst] - pos[src]
    dist = torch.linalg.vector_norm(rel, dim=-1, keepdim=True)
    push = draw(src.shape[0]) * (dist[:, 0] - radius[src] - radius[dst] < touch)
    if graph.masked:  # a fixed-capacity graph: only the edges its rules accept are contacts
        push = push * graph.pp_weight(push)[: src.shape[0]]
    along = 0.5 * push[:, None] * rel / dist.clamp_min(1e-12)
    shift.index_add_(0, dst, -along).index_add_(0, src, along)
    plane, sphere = graph.ps_index
    normal = state.planes[plane, 3:6]
    depth_now = edge_plane_depth(pos, radius, state.planes, state.plane_kind, graph.ps_index)
    push = draw(sphere.shape[0]) * (-depth_now < touch)
    if graph.masked:
        push = push * graph.ps_weight(push)
    shift.index_add_(0, sphere, -push[:, None] * normal)
    out = state.clone()
    out.pos = pos + shift
    if getattr(state, "target_vel", None) is not None:
        out.target_vel = state.target_vel - shift / state.scene_dt[:, None]
    return out
