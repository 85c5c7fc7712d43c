"""The learned simulator: scene state → graph → network → next velocities (physical units).

:class:`LearnedSimulator` joins the physics side (:mod:`physgnn.graph.builder`) and the network
(:mod:`physgnn.nn.epd`) and owns every normalisation, so the rest of physgnn (Lightning module,
rollout, evaluation) speaks physical units only.

**Target choice**: :mod:`physgnn.models.outputs`.

**Inputs** (``model.inputs``, :class:`~physgnn.models.options.ModelInputs`): the node and edge
inputs, :mod:`physgnn.models.features`; contact inputs, material values and the gravity prior
(``contact_features``, ``material_features``, ``gravity_prior``; the default model has all
three, ``model=report`` none): :mod:`physgnn.models.contact_inputs`.

**Contacts within the frame** (``contact_passes``) and the contact memory
(``contact_memory``): :mod:`physgnn.models.passes`.

**Pair impulses** (``pair_impulses=True``): sphere–sphere interactions decoded as antisymmetric
pair impulses, momentum exact for any weights (:mod:`physgnn.models.impulses`); without them
(``model=report``) every sphere decodes its own Δv.

**Reach, the latch and support**: :mod:`physgnn.models.reach` (``recent_contact`` turns the
previous default's latch back on). **Boundary features** (``boundary_features=True``, the
GNS-style baseline): :mod:`physgnn.models.boundary`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import nn

from physgnn.data.state import scene_of_sphere
from physgnn.graph.builder import GraphBuilder
from physgnn.graph.edges import Layout
from physgnn.models import boundary, contact_inputs, features, impulses, passes, reach, rest
from physgnn.models.motion import physical_motion
from physgnn.models.normalisation import (  # noqa: F401 (StatsError: re-exported)
    StatsError,
    register_stats,
    stats_from_state_dict,
)
from physgnn.models.options import ContactHandling, ModelInputs
from physgnn.models.outputs import StepOutputs, node_outputs, normalised_targets, pair_outputs
from physgnn.nn.epd import EncodeProcessDecode, Widths
from physgnn.nn.padding import pad_graph
from physgnn.physics.scene import EFFECT_NAMES

ROTATION = EFFECT_NAMES.index("rotation")
DEFAULT_INPUTS, DEFAULT_CONTACTS = ModelInputs(), ContactHandling()


class LearnedSimulator(nn.Module):
    """Graph network simulator with the normalisation of its training set kept in buffers.

    Constructor arguments are the ``model`` config keys (``conf/model/*.yaml``); ``stats`` is
    the dataset's ``stats.json`` dict (runtime object). ``network`` makes the network from the
    :class:`~physgnn.nn.epd.Widths` the simulator's inputs set (``None``:
    :class:`~physgnn.nn.epd.EncodeProcessDecode` with its defaults; the config's ``network``
    node is a partial of it); ``graph`` is the :class:`~physgnn.graph.builder.GraphBuilder`
    (``None``: one with its defaults). ``length_scale`` divides every length of the edge
    features (``None``: the mean sphere diameter of the training set). ``inputs``
    (:class:`~physgnn.models.options.ModelInputs`) says what the network sees, ``contacts``
    (:class:`~physgnn.models.options.ContactHandling`) how a step treats contacts (module doc);
    ``pad_to_buckets``: the network sees graphs padded to capacity buckets (opt-in capture
    path, :mod:`physgnn.nn.padding`). Node input per sphere: the blocks of
    :attr:`node_layout` (:mod:`physgnn.models.features`), ``6·(H+1) + 5`` numbers with the
    default inputs (masses as pair ratios, material values): 11 for the default model, H = 0.
    """

    def __init__(
        self,
        stats: dict,
        H: int = 0,
        network: Callable[..., EncodeProcessDecode] | None = None,
        graph: GraphBuilder | None = None,
        length_scale: float | None = None,
        inputs: ModelInputs = DEFAULT_INPUTS,
        contacts: ContactHandling = DEFAULT_CONTACTS,
        pad_to_buckets: bool = False,
    ):
        super().__init__()
        if H < 0:
            raise ValueError(f"need H >= 0 (got H={H})")
        self.H, self.pad_to_buckets = int(H), bool(pad_to_buckets)
        self.inputs, self.contacts = inputs, contacts
        self._register_stats(stats, length_scale)
        if inputs.engine_state:
            share = contact_inputs.gravity_share(stats)
            self.register_buffer("gravity_share", torch.tensor(share))
        self.graph_builder = GraphBuilder() if graph is None else graph
        self.network = self._network(EncodeProcessDecode if network is None else network)
        if contacts.plane_floor and contacts.plane_newton:
            impulses.start_from_the_law(self)

    def _network(self, network: Callable[..., EncodeProcessDecode]) -> EncodeProcessDecode:
        """``network`` called with the :class:`~physgnn.nn.epd.Widths` of the simulator's
        inputs."""
        widths = Widths(
            node_in=self.node_in,
            pp_in=self.pp_layout.width,
            ps_in=self.ps_layout.width,
            out_dim=self.outputs.width,
            pair_out=self.pair_outputs.width if self.contacts.pair_impulses else 0,
        )
        built = network(widths=widths)
        if len(built.blocks) < 1:
            raise ValueError(f"need M >= 1 message-passing blocks (got M={len(built.blocks)})")
        return built

    @property
    def padded(self) -> bool:
        """True when the network sees graphs padded to buckets: ``pad_to_buckets``, or a
        fixed-capacity graph builder (its masked edges need padding's ghost node)."""
        return self.pad_to_buckets or bool(getattr(self.graph_builder, "fixed_capacity", False))

    @property
    def outputs(self) -> Layout:
        """The blocks of the network's node outputs (:mod:`physgnn.models.outputs`)."""
        return node_outputs(self.contacts.rest_decision, self.inputs.engine_state)

    @property
    def pair_outputs(self) -> Layout:
        """The blocks of the network's pair outputs (with ``pair_impulses``)."""
        return pair_outputs(self.inputs.engine_state)

    @property
    def M(self) -> int:
        """The network's number of message-passing blocks."""
        return len(self.network.blocks)

    def _register_stats(self, stats: dict, length_scale: float | None) -> None:
        """:func:`~physgnn.models.normalisation.register_stats` and the effects trained on, as
        buffers (saved in checkpoints)."""
        register_stats(self, stats, length_scale)
        self.register_buffer("effects_trained", torch.zeros(len(EFFECT_NAMES), dtype=torch.bool))

    @property
    def node_layout(self) -> Layout:
        """The blocks of the network's node input (:func:`~physgnn.models.features.node_layout`)."""
        return features.node_layout(self.H, self.inputs)

    @property
    def node_in(self) -> int:
        """The number of node inputs per sphere: the width of :attr:`node_layout`."""
        return self.node_layout.width

    @property
    def pp_layout(self) -> Layout:
        """The blocks of the network's pp input (:func:`~physgnn.models.features.pp_layout`)."""
        return features.pp_layout(self.H, self.inputs)

    @property
    def ps_layout(self) -> Layout:
        """The blocks of the network's ps input (:func:`~physgnn.models.features.ps_layout`)."""
        return features.ps_layout(self.inputs)

    @property
    def speed_scale(self) -> torch.Tensor:
        """σ_v of the contact features: the RMS of the three velocity stds (m/s)."""
        return self.vel_std.square().mean().sqrt()

    @property
    def delta_spin_scale(self) -> torch.Tensor:
        """σ_Δω of the pair couples: the RMS of the three angular-velocity-change stds."""
        return self.delta_angvel_std.square().mean().sqrt()

    @property
    def delta_speed_scale(self) -> torch.Tensor:
        """σ_Δv of the contact penalty: the RMS of the three velocity-change stds (m/s)."""
        return self.delta_vel_std.square().mean().sqrt()

    stats_from_state_dict = staticmethod(stats_from_state_dict)

    # ----- features ---------------------------------------------------------------------------
    def node_features(self, state) -> torch.Tensor:
        """``[N, node_in]`` (:func:`~physgnn.models.features.node_features`)."""
        return features.node_features(self, state)

    def boundary_features(self, state) -> torch.Tensor:
        """``[N, 6]``: :func:`~physgnn.models.boundary.boundary_features` at
        ``inputs.boundary_radius``."""
        return boundary.boundary_features(state, self.inputs.boundary_radius)

    def edge_features(self, graph, state=None) -> tuple[torch.Tensor, torch.Tensor]:
        """pp ``[E, pp_layout.width]`` and ps ``[F, ps_layout.width]``
        (:func:`~physgnn.models.features.edge_features`)."""
        return features.edge_features(self, graph, state)

    def in_reach(self, state, graph) -> torch.Tensor:
        """``[N]`` bool: spheres that may touch something before the next frame
        (:func:`~physgnn.models.reach.contact_reach`)."""
        return self.reach(state, graph).spheres

    def reach(self, state, graph, provisional: Sequence = ()) -> reach.Reach:
        """:func:`~physgnn.models.reach.contact_reach` of ``graph`` (built with
        ``provisional``)."""
        builder = self.graph_builder
        latch = self.contacts.recent_contact
        return reach.contact_reach(state, graph, builder, provisional, latch)

    def rotating(self, state) -> torch.Tensor:
        """``[N]`` bool: spheres whose scene has the rotation effect on."""
        return state.effects[scene_of_sphere(state), ROTATION]

    # ----- prediction -------------------------------------------------------------------------
    def normalized_prediction(self, state):
        """Network output ``[N, 6]`` (normalised Δv, Δω) and the graph it was computed on."""
        graph = self.graph_builder(state)
        return self.network_prediction(state, graph), graph

    def network_prediction(self, state, graph, on_plane=None, memory=None) -> torch.Tensor:
        """Network output ``[N, 6]`` (normalised Δv, Δω; then the rest logit) on ``graph``,
        built from ``state``. With ``pair_impulses`` the Δv and Δω are the pair impulses' and,
        for spheres ``on_plane [N]`` (None: :meth:`reach`'s), the node decoder's own, plus
        gravity, in the same normalised units. ``memory``: a
        :class:`~physgnn.models.passes.PassMemory` of the step's passes."""
        x = self.node_features(state)
        edges = graph.network_inputs(x.shape[0], *self.edge_features(graph, state))
        material = state.material if self.network.material is not None else None
        pairs = self.contacts.pair_impulses
        run = passes.network_call(self.network, pairs, memory)
        # fixed shapes for a captured step (physgnn/nn/padding.py); a fixed-capacity graph's
        # masked edges need padding's ghost node (self.padded says so)
        if self.padded:
            padded, n = pad_graph(x, *edges, material)
            out = run(*padded)
            out = (out[0][:n], out[1]) if pairs else out[:n]
        else:
            out = run(x, *edges, material)
        if not pairs:
            return out
        if on_plane is None:
            on_plane = self.reach(state, graph).planes
        return impulses.normalised_changes(self, state, graph, *out, on_plane)

    def normalized_target(self, state) -> torch.Tensor:
        """``[N, regression(outputs).width]``: the state's targets as the network's
        regression outputs (:func:`~physgnn.models.outputs.normalised_targets`)."""
        return normalised_targets(self, state)

    def rest_target(self, state) -> torch.Tensor:
        """``[N]`` bool: the rest decision's label (:func:`~physgnn.models.rest.rest_target`)."""
        return rest.rest_target(state, self.contacts.rest_speed)

    def to_physical(
        self, state, pred: torch.Tensor, reach: torch.Tensor | None = None, supported=None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Normalised output ``[N, outputs.width]`` → ``(v_{t+1} [N, 3], ω_{t+1} [N, 3])``, the
        first two of :meth:`motion`."""
        return self.motion(state, pred, reach, supported)[:2]

    def motion(self, state, pred: torch.Tensor, reach=None, supported=None, graph=None) -> tuple:
        """Normalised output → ``(v_{t+1}, ω_{t+1}, ū, ω̄)`` ``[N, 3]`` each
        (:func:`~physgnn.models.motion.physical_motion`; ``graph``: the step's)."""
        return physical_motion(self, state, pred, reach, supported, graph)

    def forward(self, state) -> tuple[torch.Tensor, ...]:
        """``(vel_next [N, 3], angvel_next [N, 3])`` in physical units (m/s, rad/s, world
        frame); with the engine state also the frame's mean motion ``(ū [N, 3], ω̄ [N, 3])``,
        what moves the spheres (:func:`~physgnn.models.protocol.motion_of`)."""
        motion, _ = self.predict_motion(state)
        return motion if self.inputs.engine_state else motion[:2]

    def predict(self, state):
        """``(vel_next [N, 3], angvel_next [N, 3], graph)`` of :meth:`predict_motion`."""
        motion, graph = self.predict_motion(state)
        return motion[0], motion[1], graph

    def predict_motion(self, state):
        """``((v_{t+1}, ω_{t+1}, ū, ω̄), graph)`` of the last pass
        (:func:`~physgnn.models.passes.predict_motion`; the graph for a constraint stage,
        :mod:`physgnn.models.constrained`)."""
        return passes.predict_motion(self, state)

    def recalled(self, state) -> tuple[torch.Tensor, ...]:
        """The velocities the rules also link by (:func:`~physgnn.models.passes.recalled`)."""
        return passes.recalled(self.contacts, state)

    def head(self, state, graph, provisional: Sequence = (), memory=None) -> tuple:
        """``(v_{t+1}, ω_{t+1}, ū, ω̄)`` ``[N, 3]`` each of :meth:`step`: everything of a step
        after the graph build, the region a compiled simulator compiles as one
        (:mod:`physgnn.models.capture`)."""
        outputs = self.step(state, graph, provisional, memory)
        return outputs.vel, outputs.angvel, outputs.mean_vel, outputs.mean_angvel

    def step(self, state, graph, provisional: Sequence = (), memory=None) -> StepOutputs:
        """One step on ``graph`` (built from ``state`` with ``provisional`` velocities): reach,
        features, network (``memory``: :meth:`network_prediction`'s), physical units. The one
        step function: the rollout (:meth:`head`) and the training loss
        (:meth:`~physgnn.training.lit.LitSimulator.graph_losses`) both call it."""
        if not self.contacts.gravity_prior:
            pred = self.network_prediction(state, graph, memory=memory)
            return StepOutputs(pred, *self.motion(state, pred), None)
        where = self.reach(state, graph, provisional)
        pred = self.network_prediction(state, graph, where.planes, memory)
        motion = self.motion(state, pred, where.spheres, where.supported, graph)
        return StepOutputs(pred, *motion, where.spheres)
