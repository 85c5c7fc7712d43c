"""What the learned simulator's network sees: its node and edge inputs, each a named block of
columns (as :mod:`physgnn.graph.edges` names the edge blocks and :mod:`physgnn.models.outputs`
the outputs), for a model's history ``H`` and its
:class:`~physgnn.models.options.ModelInputs`.

Node input per sphere (:func:`node_layout`), in order: ``vel`` ``3·(H+1)``, the H+1 latest
velocities ``(v − μ_v)/σ_v``; ``angvel`` ``3·(H+1)``, likewise ``(ω − μ_ω)/σ_ω``; ``radius``
(1), standardised; ``mass`` (1), standardised, unless ``mass_ratio`` (masses then enter as pair
ratios only); ``material`` (4) with ``material_features``
(:func:`~physgnn.models.contact_inputs.material_features`); ``boundary`` (6) with
``boundary_features`` (:func:`~physgnn.models.boundary.boundary_features` at
``boundary_radius``). Absolute position and orientation are masked.

Edge inputs: the graph's blocks (:data:`~physgnn.graph.edges.PP`,
:data:`~physgnn.graph.edges.PS`) with lengths over ``length_scale`` and the ps velocity over
σ_v per axis, then the blocks of the model's inputs (:mod:`physgnn.models.contact_inputs`):
:func:`pp_layout`, :func:`ps_layout`.
"""

from __future__ import annotations

import torch

from physgnn.graph.edges import PS, Layout, pp_inputs, ps_inputs
from physgnn.models import boundary, contact_inputs
from physgnn.models.options import ModelInputs


def node_layout(H: int, inputs: ModelInputs) -> Layout:
    """The blocks of the node input of a model with history ``H`` (module doc)."""
    blocks = [("vel", 3 * (H + 1)), ("angvel", 3 * (H + 1)), ("radius", 1)]
    if not inputs.mass_ratio:
        blocks.append(("mass", 1))
    if inputs.material_features:
        blocks.append(("material", 4))
    if inputs.boundary_features:
        blocks.append(("boundary", 6))
    return Layout(tuple(blocks))


def pp_layout(H: int, inputs: ModelInputs) -> Layout:
    """The blocks of the pp input (:func:`~physgnn.graph.edges.pp_inputs`)."""
    flags = inputs.relative_pairs, inputs.mass_ratio, inputs.material_features
    return pp_inputs(H + 1, *flags, inputs.contact_features)


def ps_layout(inputs: ModelInputs) -> Layout:
    """The blocks of the ps input (:func:`~physgnn.graph.edges.ps_inputs`)."""
    return ps_inputs(inputs.contact_features, carries_plane_materials(inputs))


def carries_plane_materials(inputs: ModelInputs) -> bool:
    """ps edges carry the contact's restitution and lateral friction: ``plane_materials``, which
    needs ``material_features`` (the sphere's values, times the plane's)."""
    return inputs.plane_materials and inputs.material_features


def node_features(sim, state) -> torch.Tensor:
    """``[N, node_layout(H, inputs).width]`` of ``sim`` (a
    :class:`~physgnn.models.learned.LearnedSimulator`); a state with a longer history uses its
    H+1 latest velocities."""
    inputs, h = sim.inputs, sim.H + 1
    vel, angvel = state.vel[:, :h], state.angvel[:, :h]
    if vel.shape[1] != h:
        raise ValueError(f"state has {vel.shape[1]} velocities of history, model needs {h}")
    parts = {
        "vel": ((vel - sim.vel_mean) / sim.vel_std).flatten(1),
        "angvel": ((angvel - sim.angvel_mean) / sim.angvel_std).flatten(1),
        "radius": ((state.radius - sim.radius_mean) / sim.radius_std)[:, None],
    }
    if not inputs.mass_ratio:
        parts["mass"] = ((state.mass - sim.mass_mean) / sim.mass_std)[:, None]
    if inputs.material_features:
        parts["material"] = contact_inputs.material_features(state)
    if inputs.boundary_features:
        parts["boundary"] = boundary.boundary_features(state, inputs.boundary_radius)
    return node_layout(sim.H, inputs).join(parts)


def edge_features(sim, graph, state=None) -> tuple[torch.Tensor, torch.Tensor]:
    """pp ``[E, pp_layout.width]`` and ps ``[F, ps_layout.width]`` of ``sim`` on ``graph``
    (module doc; the blocks of the model's inputs need ``state``)."""
    inputs = sim.inputs
    pp_attr = graph.pp_attr / sim.length_scale  # both PP blocks are lengths
    ps = graph.ps_attr
    ps_attr = PS.join(
        {
            "velocity": PS.take(ps, "velocity") / sim.vel_std,
            "normal": PS.take(ps, "normal"),
            "offset": PS.take(ps, "offset") / sim.length_scale,
            "height": PS.take(ps, "height") / sim.length_scale,
        }
    )
    scales = sim.length_scale, sim.speed_scale
    if inputs.relative_pairs:
        flags = sim.H + 1, inputs.mass_ratio, inputs.material_features
        pair = contact_inputs.pair_inputs(graph, state, *scales, *flags)
        pp_attr = torch.cat([pp_attr, pair], 1)
    elif inputs.contact_features:
        pp_attr = torch.cat([pp_attr, contact_inputs.pp_contact(graph, state, *scales)], 1)
    if inputs.contact_features:
        ps_attr = torch.cat([ps_attr, contact_inputs.ps_contact(graph, state, *scales)], 1)
    if carries_plane_materials(inputs):
        ps_attr = torch.cat([ps_attr, contact_inputs.ps_material(graph, state)], 1)
    return pp_attr, ps_attr
