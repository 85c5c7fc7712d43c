"""The learned simulator's output contract: each output a named block of columns (as
:mod:`physgnn.graph.edges` names the edge inputs), and :class:`StepOutputs`, the result of one
step that the rollout and the training loss both read.

No column of an output is numbered by hand anywhere else: writers join blocks by name, readers
take them by name (:class:`~physgnn.graph.edges.Layout`).

- Node outputs ``[N, node_outputs(rest, engine).width]``, normalised with the training
  statistics (the target choice below): ``delta_vel`` (3)
  ``(Δv − μ_Δv)/σ_Δv`` and ``delta_angvel`` (3) ``(Δω − μ_Δω)/σ_Δω``, the change of the
  velocities from ``v_t`` to the next state's ``v_{t+1}``; with the engine state
  (``engine_state``: the state is the engine's end-of-frame velocity, not the frame's mean) also
  ``delta_mean_vel`` (3) ``(ū − v_t − μ_Δv)/σ_Δv`` and ``delta_mean_angvel`` (3)
  ``(ω̄ − ω_t − μ_Δω)/σ_Δω``, the frame's mean motion ``ū = Δp/dt``, ``ω̄ = θ/dt``; then, with
  the rest decision, ``rest`` (1), the logit of "at rest next frame"
  (:mod:`physgnn.models.rest`). With pair impulses the velocity changes are the pair impulses'
  changes plus gravity plus, for spheres near a plane, the node decoder's own
  (:func:`~physgnn.models.impulses.normalised_changes`).
- Pair outputs :data:`PAIR` ``[E/2, 6]`` (pair impulses, one row per pair, antisymmetric:
  :class:`~physgnn.nn.pair_decoder.PairDecoder`): ``impulse`` (3), the normalised impulse on
  the pair's target sphere; ``couple`` (3), its normalised couple
  (:mod:`physgnn.models.impulses`); with the engine state (:data:`PAIR_ENGINE`, ``[E/2, 12]``)
  also ``mean_impulse`` and ``mean_couple``, the same rule for the frame's mean motion, so that
  an isolated group's centre of mass moves exactly as a ballistic point.

**Target choice.** The network predicts the normalised *change* of the velocities,
``((v_{t+1} − v_t) − μ_Δv) / σ_Δv`` and ``((ω_{t+1} − ω_t) − μ_Δω) / σ_Δω`` (``delta_vel`` /
``delta_angvel`` statistics of the training split), as GNS does with accelerations. For a given
input state ``v_t`` is known, so this is an affine map of the report's target ``v_{t+1}``: the
same function is learned, but the regression target has unit scale whatever the speed, and
"nothing changes" is the output ``−μ/σ`` rather than a copy of the input. With input noise the
target ``v_{t+1}`` stays the clean one while ``v_t`` is the noisy input, so the network also
learns to undo the noise. The regression targets: :func:`normalised_targets`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import torch

from physgnn.graph.edges import Layout

VELOCITY_CHANGES = (("delta_vel", 3), ("delta_angvel", 3))
MEAN_CHANGES = (("delta_mean_vel", 3), ("delta_mean_angvel", 3))
NODE = Layout(VELOCITY_CHANGES)
NODE_REST = Layout((*VELOCITY_CHANGES, ("rest", 1)))
NODE_ENGINE = Layout((*VELOCITY_CHANGES, *MEAN_CHANGES))
NODE_ENGINE_REST = Layout((*VELOCITY_CHANGES, *MEAN_CHANGES, ("rest", 1)))
PAIR = Layout((("impulse", 3), ("couple", 3)))
PAIR_ENGINE = Layout((("impulse", 3), ("couple", 3), ("mean_impulse", 3), ("mean_couple", 3)))


def node_outputs(rest_decision: bool, engine_state: bool = False) -> Layout:
    """The node outputs of a model: the velocity changes, the mean changes with the engine
    state, then the rest logit with the rest decision."""
    if engine_state:
        return NODE_ENGINE_REST if rest_decision else NODE_ENGINE
    return NODE_REST if rest_decision else NODE


def pair_outputs(engine_state: bool = False) -> Layout:
    """The pair outputs of a model with pair impulses: :data:`PAIR`, or :data:`PAIR_ENGINE`
    (an impulse and a couple for the end velocities and for the frame's mean motion)."""
    return PAIR_ENGINE if engine_state else PAIR


def regression(layout: Layout) -> Layout:
    """The blocks of ``layout`` that the regression loss compares with a target (every block
    but the rest logit)."""
    return Layout(tuple(b for b in layout.blocks if b[0] != "rest"))


def velocity_changes(out: torch.Tensor, layout: Layout = NODE) -> torch.Tensor:
    """``[N, regression(layout).width]``: the normalised velocity-change blocks of node outputs
    ``out`` (the rest logit, always last, left out)."""
    return out[:, : regression(layout).width]


@functools.cache
def angular_columns(layout: Layout) -> tuple[slice, ...]:
    """The column ranges of angular changes in ``regression(layout)`` (left out of the loss
    for spheres of a scene without rotation); host slices, nothing copied to a device."""
    regressed = regression(layout)
    return tuple(regressed.slice(name) for name in regressed.names if name.endswith("angvel"))


@dataclass(frozen=True)
class StepOutputs:
    """One learned step on one graph (:meth:`~physgnn.models.learned.LearnedSimulator.step`).

    - ``out [N, node_outputs(rest).width]``: the normalised node outputs (module doc);
    - ``vel [N, 3]``, ``angvel [N, 3]``: ``v_{t+1}``, ``ω_{t+1}`` in physical units, after the
      gravity prior, the rest decision and the rotation effect: the next state's velocities;
    - ``mean_vel [N, 3]``, ``mean_angvel [N, 3]``: the frame's motion, ``(p_{t+1} − p_t)/dt``
      and ``log(q_{t+1} ⊗ q_t⁻¹)/dt``, what moves the sphere; the same tensors as ``vel`` and
      ``angvel`` for a finite-difference state (whose velocity *is* the frame's motion);
    - ``reach [N]`` bool: the spheres in reach of a contact, which the network answers for
      (the others fly ballistically); None without the gravity prior (every sphere).
    """

    out: torch.Tensor
    vel: torch.Tensor
    angvel: torch.Tensor
    mean_vel: torch.Tensor
    mean_angvel: torch.Tensor
    reach: torch.Tensor | None


def normalised_targets(sim, state) -> torch.Tensor:
    """``[N, regression(sim.outputs).width]``: the normalised change from the state's (possibly
    noisy) ``v_t, ω_t`` to its targets ``v_{t+1}, ω_{t+1}`` and, with the engine state, to the
    frame's mean motion ``ū, ω̄`` (``target_mean_vel``, ``target_mean_angvel``; a state without
    them has finite differences, whose mean motion is its velocity) (module doc)."""
    if getattr(state, "target_vel", None) is None:
        raise ValueError("state has no target_vel / target_angvel (last frame of a trajectory?)")
    targets = [state.target_vel, state.target_angvel]
    if sim.inputs.engine_state:
        mean = getattr(state, "target_mean_vel", None)
        spin = getattr(state, "target_mean_angvel", None)
        targets += [targets[0] if mean is None else mean, targets[1] if spin is None else spin]
    return torch.cat([_normalised_change(sim, state, t, k) for k, t in enumerate(targets)], 1)


def _normalised_change(sim, state, target: torch.Tensor, k: int) -> torch.Tensor:
    """``(target − x_t − μ)/σ``: a linear (k even) or angular (k odd) velocity target as the
    normalised change from the state's latest velocity."""
    if k % 2 == 0:
        return (target - state.vel[:, 0] - sim.delta_vel_mean) / sim.delta_vel_std
    return (target - state.angvel[:, 0] - sim.delta_angvel_mean) / sim.delta_angvel_std
