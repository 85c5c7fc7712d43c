"""The learned simulator: scene state → graph → network → next velocities (physical units).

:class:`LearnedSimulator` joins the physics side (:mod:`physgnn.graph.builder`) and the network
(:mod:`physgnn.nn.epd`) and owns every normalisation, so the rest of physgnn (Lightning module,
rollout, evaluation) speaks physical units only.

**Target choice.** The network predicts the normalised *change* of the velocities,
``((v_{t+1} − v_t) − μ_Δv) / σ_Δv`` and ``((ω_{t+1} − ω_t) − μ_Δω) / σ_Δω`` (``delta_vel`` /
``delta_angvel`` statistics of the training split), as GNS does with accelerations. For a given
input state ``v_t`` is known, so this is an affine map of the report's target ``v_{t+1}``: the
same function is learned, but the regression target has unit scale whatever the speed, and
"nothing changes" is the output ``−μ/σ`` rather than a copy of the input. With input noise the
target ``v_{t+1}`` stays the clean one while ``v_t`` is the noisy input, so the network also
learns to undo the noise.

**Contact inputs, material values, gravity prior** (``contact_features``,
``material_features``, ``gravity_prior``; the default model has all three, ``model=report``
none): :mod:`physgnn.models.contact_inputs`.

**Contacts within the frame** (``contact_passes`` = K > 0): after a pass, the graph is built
again with the pass's provisional next velocities (spheres in reach take the network's, the
others their ballistic one; :class:`~physgnn.graph.builder.GraphBuilder`, "Contacts within the
frame") and the network passes again, while a rebuild adds edges, at most K times. A counted
graph knows its size on the host after its build, so stopping reads nothing more back; a
fixed-capacity graph always makes K passes.

**Pair impulses** (``pair_impulses=True``): sphere–sphere interactions are decoded as
antisymmetric pair impulses applied at the contact point (:mod:`physgnn.models.impulses`);
only a sphere near a plane takes a change of its own from the node decoder (planes and gravity
are external), so linear and angular momentum are conserved exactly for any weights. Without it
(the previous default, ``model=report``) every sphere decodes its own Δv.

**Contact memory** (``contact_memory=True``, opt-in): the rules also link by the last frame's
motion reversed (``−v_t``: since ``p_t − p_{t−1} = dt·v_t``, a pair or a plane that could have
touched during the last frame), so a contact keeps its edges one frame after it parts. The
finite-difference velocity of a frame that held a bounce is the frame's mean, not the physical
velocity after the bounce; with the memory the network may correct it the frame after, where
without it the sphere is already ballistic. Unlike the latch, input noise does not trip it.

**Reach, the latch and support**: :mod:`physgnn.models.reach` (``recent_contact`` turns the
previous default's latch back on).

**Boundary features** (``boundary_features=True``, the GNS-style baseline):
:mod:`physgnn.models.boundary`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import nn

from physgnn.data.state import scene_of_sphere
from physgnn.graph.builder import GraphBuilder
from physgnn.graph.edges import PS, Layout, pp_inputs, ps_inputs
from physgnn.models import boundary, contact_inputs, impulses, reach, rest
from physgnn.models.motion import physical_motion
from physgnn.models.normalisation import (  # noqa: F401 (StatsError: re-exported)
    StatsError,
    register_stats,
    stats_from_state_dict,
)
from physgnn.models.options import ContactHandling, ModelInputs
from physgnn.models.outputs import StepOutputs, node_outputs, pair_outputs
from physgnn.models.protocol import motion_of
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
    features (``None``: the mean sphere diameter of the training set); velocities in edge
    features are divided by the velocity std. ``inputs``
    (:class:`~physgnn.models.options.ModelInputs`) says what the network sees, ``contacts``
    (:class:`~physgnn.models.options.ContactHandling`) how a step treats contacts. Node input
    per sphere:
    ``[(v − μ_v)/σ_v for the H+1 latest v, (ω − μ_ω)/σ_ω likewise, radius, mass (standardised)]``
    = ``6·(H+1) + 2`` numbers, plus 4 with ``material_features``, plus 6 with
    ``boundary_features`` (:meth:`boundary_features`, ``boundary_radius`` R in metres);
    absolute position and orientation are masked. ``contact_features``, ``gravity_prior``: see
    the module doc; ``pad_to_buckets``: the network sees graphs padded to capacity buckets
    (opt-in capture path, :mod:`physgnn.nn.padding`). ``contact_passes``, ``pair_impulses``,
    ``recent_contact``, ``contact_memory``: the module doc; ``plane_materials``: ps edges also
    carry the contact's restitution and lateral friction, the sphere's times the plane's (needs
    ``material_features``).
    """

    def __init__(
        self,
        stats: dict,
        H: int = 2,
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
        self.use_boundary, self.boundary_radius = inputs.boundary_features, inputs.boundary_radius
        self.contact_features = inputs.contact_features
        self.material_features = inputs.material_features
        self.relative_pairs, self.mass_ratio = inputs.relative_pairs, inputs.mass_ratio
        self.plane_materials = inputs.plane_materials and self.material_features
        self.gravity_prior = contacts.gravity_prior
        self.rest_decision, self.rest_speed = contacts.rest_decision, float(contacts.rest_speed)
        self.contact_passes = int(contacts.contact_passes)
        self.pair_impulses = contacts.pair_impulses
        self.latch, self.contact_memory = contacts.recent_contact, contacts.contact_memory
        self.engine_state = inputs.engine_state
        self._register_stats(stats, length_scale)
        if self.engine_state:
            share = contact_inputs.gravity_share(stats)
            self.register_buffer("gravity_share", torch.tensor(share))
        self.graph_builder = GraphBuilder() if graph is None else graph
        self.network = self._network(EncodeProcessDecode if network is None else network)

    def _network(self, network: Callable[..., EncodeProcessDecode]) -> EncodeProcessDecode:
        """``network`` called with the :class:`~physgnn.nn.epd.Widths` of the simulator's
        inputs."""
        widths = Widths(
            node_in=self.node_in,
            pp_in=self.pp_layout.width,
            ps_in=self.ps_layout.width,
            out_dim=self.outputs.width,
            pair_out=self.pair_outputs.width if self.pair_impulses else 0,
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
        return node_outputs(self.rest_decision, self.engine_state)

    @property
    def pair_outputs(self) -> Layout:
        """The blocks of the network's pair outputs (with ``pair_impulses``)."""
        return pair_outputs(self.engine_state)

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
    def node_in(self) -> int:
        extra = (4 if self.material_features else 0) + (6 if self.use_boundary else 0)
        return 6 * (self.H + 1) + 1 + int(not self.mass_ratio) + extra

    @property
    def pp_layout(self) -> Layout:
        """The blocks of the network's pp input (:func:`~physgnn.graph.edges.pp_inputs`)."""
        flags = self.relative_pairs, self.mass_ratio, self.material_features
        return pp_inputs(self.H + 1, *flags, self.contact_features)

    @property
    def ps_layout(self) -> Layout:
        """The blocks of the network's ps input (:func:`~physgnn.graph.edges.ps_inputs`)."""
        return ps_inputs(self.contact_features, self.plane_materials)

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
        """``[N, node_in]``: ``[N, 6·(H+1) + 2]`` then, with ``boundary_features``, the
        ``[N, 6]`` of :meth:`boundary_features`; a state with a longer history uses its H+1
        latest velocities."""
        vel = state.vel[:, : self.H + 1]
        angvel = state.angvel[:, : self.H + 1]
        if vel.shape[1] != self.H + 1:
            raise ValueError(
                f"state has {vel.shape[1]} velocities of history, model needs {self.H + 1}"
            )
        vel = (vel - self.vel_mean) / self.vel_std
        angvel = (angvel - self.angvel_mean) / self.angvel_std
        radius = (state.radius - self.radius_mean) / self.radius_std
        parts = [vel.flatten(1), angvel.flatten(1), radius[:, None]]
        if not self.mass_ratio:  # else masses enter as pair ratios only
            parts.append(((state.mass - self.mass_mean) / self.mass_std)[:, None])
        if self.material_features:
            parts.append(contact_inputs.material_features(state))
        if self.use_boundary:
            parts.append(self.boundary_features(state))
        return torch.cat(parts, 1)

    def boundary_features(self, state) -> torch.Tensor:
        """``[N, 6]``: :func:`~physgnn.models.boundary.boundary_features` at
        ``boundary_radius``."""
        return boundary.boundary_features(state, self.boundary_radius)

    def edge_features(self, graph, state=None) -> tuple[torch.Tensor, torch.Tensor]:
        """pp ``[E, pp_layout.width]`` and ps ``[F, ps_layout.width]``
        (:mod:`physgnn.graph.edges`): the graph's blocks, lengths / length_scale, the ps
        velocity / σ_v per axis, the normal unchanged; then the blocks of the model's options
        (:mod:`physgnn.models.contact_inputs`; they need ``state``)."""
        pp_attr = graph.pp_attr / self.length_scale  # both PP blocks are lengths
        ps = graph.ps_attr
        ps_attr = PS.join(
            {
                "velocity": PS.take(ps, "velocity") / self.vel_std,
                "normal": PS.take(ps, "normal"),
                "offset": PS.take(ps, "offset") / self.length_scale,
                "height": PS.take(ps, "height") / self.length_scale,
            }
        )
        scales = self.length_scale, self.speed_scale
        if self.relative_pairs:
            flags = self.H + 1, self.mass_ratio, self.material_features
            pair = contact_inputs.pair_inputs(graph, state, *scales, *flags)
            pp_attr = torch.cat([pp_attr, pair], 1)
        elif self.contact_features:
            pp_attr = torch.cat([pp_attr, contact_inputs.pp_contact(graph, state, *scales)], 1)
        if self.contact_features:
            ps_attr = torch.cat([ps_attr, contact_inputs.ps_contact(graph, state, *scales)], 1)
        if self.plane_materials:
            ps_attr = torch.cat([ps_attr, contact_inputs.ps_material(graph, state)], 1)
        return pp_attr, ps_attr

    def in_reach(self, state, graph) -> torch.Tensor:
        """``[N]`` bool: spheres that may touch something before the next frame
        (:func:`~physgnn.models.reach.contact_reach`)."""
        return self.reach(state, graph).spheres

    def reach(self, state, graph, provisional: Sequence = ()) -> reach.Reach:
        """:func:`~physgnn.models.reach.contact_reach` of ``graph`` (built with
        ``provisional``)."""
        builder = self.graph_builder
        return reach.contact_reach(state, graph, builder, provisional, self.latch)

    def rotating(self, state) -> torch.Tensor:
        """``[N]`` bool: spheres whose scene has the rotation effect on."""
        return state.effects[scene_of_sphere(state), ROTATION]

    # ----- prediction -------------------------------------------------------------------------
    def normalized_prediction(self, state):
        """Network output ``[N, 6]`` (normalised Δv, Δω) and the graph it was computed on."""
        graph = self.graph_builder(state)
        return self.network_prediction(state, graph), graph

    def network_prediction(self, state, graph, on_plane=None) -> torch.Tensor:
        """Network output ``[N, 6]`` (normalised Δv, Δω; then the rest logit) on ``graph``,
        built from ``state``. With ``pair_impulses`` the Δv and Δω are the pair impulses' and,
        for spheres ``on_plane [N]`` (None: :meth:`reach`'s), the node decoder's own, plus
        gravity, in the same normalised units."""
        x = self.node_features(state)
        edges = graph.network_inputs(x.shape[0], *self.edge_features(graph, state))
        material = state.material if self.network.material is not None else None
        run = self.network.forward_pairs if self.pair_impulses else self.network
        # fixed shapes for a captured step (physgnn/nn/padding.py); a fixed-capacity graph's
        # masked edges need padding's ghost node (self.padded says so)
        if self.padded:
            padded, n = pad_graph(x, *edges, material)
            out = run(*padded)
            out = (out[0][:n], out[1]) if self.pair_impulses else out[:n]
        else:
            out = run(x, *edges, material)
        if not self.pair_impulses:
            return out
        if on_plane is None:
            on_plane = self.reach(state, graph).planes
        return impulses.normalised_changes(self, state, graph, *out, on_plane)

    def normalized_target(self, state) -> torch.Tensor:
        """``[N, 6]``: the normalised change from the state's (possibly noisy) ``v_t, ω_t`` to
        its targets ``v_{t+1}, ω_{t+1}``."""
        if getattr(state, "target_vel", None) is None:
            raise ValueError(
                "state has no target_vel / target_angvel (last frame of a trajectory?)"
            )
        targets = [state.target_vel, state.target_angvel]
        if self.engine_state:  # a state without mean targets has finite differences: the same
            mean = getattr(state, "target_mean_vel", None)
            spin = getattr(state, "target_mean_angvel", None)
            targets += [targets[0] if mean is None else mean, targets[1] if spin is None else spin]
        return torch.cat([self._normalised_change(state, t, k) for k, t in enumerate(targets)], 1)

    def _normalised_change(self, state, target: torch.Tensor, k: int) -> torch.Tensor:
        """``(target − x_t − μ)/σ``: a linear (k even) or angular (k odd) velocity target as the
        normalised change from the state's latest velocity."""
        if k % 2 == 0:
            return (target - state.vel[:, 0] - self.delta_vel_mean) / self.delta_vel_std
        return (target - state.angvel[:, 0] - self.delta_angvel_mean) / self.delta_angvel_std

    def rest_target(self, state) -> torch.Tensor:
        """``[N]`` bool: the rest decision's label (:func:`~physgnn.models.rest.rest_target`)."""
        return rest.rest_target(state, self.rest_speed)

    def to_physical(
        self, state, pred: torch.Tensor, reach: torch.Tensor | None = None, supported=None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Normalised output ``[N, outputs.width]`` → ``(v_{t+1} [N, 3], ω_{t+1} [N, 3])``, the
        first two of :meth:`motion`."""
        return self.motion(state, pred, reach, supported)[:2]

    def motion(self, state, pred: torch.Tensor, reach=None, supported=None) -> tuple:
        """Normalised output → ``(v_{t+1}, ω_{t+1}, ū, ω̄)`` ``[N, 3]`` each
        (:func:`~physgnn.models.motion.physical_motion`)."""
        return physical_motion(self, state, pred, reach, supported)

    def forward(self, state) -> tuple[torch.Tensor, ...]:
        """``(vel_next [N, 3], angvel_next [N, 3])`` in physical units (m/s, rad/s, world
        frame); with the engine state also the frame's mean motion ``(ū [N, 3], ω̄ [N, 3])``,
        what moves the spheres (:func:`~physgnn.models.protocol.motion_of`)."""
        motion, _ = self.predict_motion(state)
        return motion if self.engine_state else motion[:2]

    def predict(self, state):
        """``(vel_next [N, 3], angvel_next [N, 3], graph)`` of :meth:`predict_motion`."""
        motion, graph = self.predict_motion(state)
        return motion[0], motion[1], graph

    def predict_motion(self, state):
        """``((v_{t+1}, ω_{t+1}, ū, ω̄), graph)``: :meth:`head` of the last pass and the graph
        it was computed on (for a constraint stage, :mod:`physgnn.models.constrained`): passes
        while a rebuild on the provisional motion adds edges, at most ``contact_passes``
        rebuilds (module doc)."""
        provisional = list(self.recalled(state))
        graph, basis = self.graph_builder.build(state, provisional)
        motion = self.head(state, graph, tuple(provisional))
        for _ in range(self.contact_passes):
            (vel, _), mean = motion_of(motion)
            provisional.append(vel if mean is None else mean[0])
            wider, basis = self.graph_builder.extend(state, basis, provisional)
            if not wider.grew(graph):
                break
            graph = wider
            motion = self.head(state, graph, tuple(provisional))
        return motion, graph

    def recalled(self, state) -> tuple[torch.Tensor, ...]:
        """With ``contact_memory``, ``(−v_t,)``: the last frame's motion reversed, as a velocity
        the rules also link by, so that a contact of the last frame keeps its edges for one
        more frame (module doc); else ``()``."""
        return (-state.vel[:, 0],) if self.contact_memory else ()

    def head(self, state, graph, provisional: Sequence = ()) -> tuple[torch.Tensor, ...]:
        """``(v_{t+1}, ω_{t+1}, ū, ω̄)`` ``[N, 3]`` each of :meth:`step`: everything of a step
        after the graph build, the region a compiled simulator compiles as one
        (:mod:`physgnn.models.capture`)."""
        outputs = self.step(state, graph, provisional)
        return outputs.vel, outputs.angvel, outputs.mean_vel, outputs.mean_angvel

    def step(self, state, graph, provisional: Sequence = ()) -> StepOutputs:
        """One step on ``graph`` (built from ``state`` with ``provisional`` velocities): reach,
        features, network, physical units. The one step function: the rollout (:meth:`head`)
        and the training loss (:meth:`~physgnn.training.lit.LitSimulator.graph_losses`) both
        call it."""
        if not self.gravity_prior:
            pred = self.network_prediction(state, graph)
            return StepOutputs(pred, *self.motion(state, pred), None)
        where = self.reach(state, graph, provisional)
        pred = self.network_prediction(state, graph, where.planes)
        motion = self.motion(state, pred, where.spheres, where.supported)
        return StepOutputs(pred, *motion, where.spheres)
