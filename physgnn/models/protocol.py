"""The :class:`Simulator` protocol: all that the rollout, the sleeping wrapper and the timer
rely on, in one place.

Required: ``H`` (the model sees the ``H + 1`` latest velocities) and the call
``simulator(state) -> (vel_next [N, 3], angvel_next [N, 3])`` on a batched
:class:`~physgnn.data.state.SceneState`, in physical units: with a finite-difference state the
velocities of the next frame, which also move the spheres. A simulator of the engine state
answers four tensors, ``(v_{t+1}, ω_{t+1}, ū, ω̄)``: the next state's end-of-frame velocities,
then the frame's mean motion that moves the spheres (:func:`motion_of` reads either). Optional
hooks, read once by :func:`hooks_of` (an absent hook means its default):

- ``inputs.engine_state`` (bool, of the innermost simulator's ``inputs``, as
  :class:`~physgnn.models.options.ModelInputs` names it): the states it takes carry the
  engine's end-of-frame velocities (:class:`~physgnn.data.state.TrajectoryFrames`;
  :func:`engine_state_of`);
- ``effects_trained [5]`` bool: effects seen in training (a rollout warns about the others);
- ``parameters()``: the rollout runs on the device of the first parameter (else the CPU);
- ``hold(pos, quat, pos_next, quat_next)``: keeps spheres in place after integration;
- ``select(keep [N] bool)``: the rollout dropped spheres (finished scenes) from its batch;
- ``graph_builder``: the :class:`~physgnn.graph.builder.GraphBuilder` whose pair rule a
  sleeping wrapper respects and whose time a :class:`~physgnn.models.profiling.StepTimer`
  measures; ``simulator``: the simulator a wrapper wraps.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch


@runtime_checkable
class Simulator(Protocol):
    H: int

    def __call__(self, state) -> tuple[torch.Tensor, torch.Tensor]: ...


@dataclass(frozen=True)
class Hooks:
    """The optional hooks of one simulator (None: absent)."""

    history: int | None
    effects_trained: torch.Tensor | None
    device: torch.device
    hold: Callable | None
    select: Callable | None
    engine_state: bool = False


def hooks_of(simulator) -> Hooks:
    """Read the protocol's optional hooks of ``simulator`` once."""
    history = getattr(simulator, "H", None)
    parameters = getattr(simulator, "parameters", None)
    first = next(parameters(), None) if callable(parameters) else None
    return Hooks(
        history=history if isinstance(history, int) else None,
        effects_trained=getattr(simulator, "effects_trained", None),
        device=first.device if first is not None else torch.device("cpu"),
        hold=getattr(simulator, "hold", None),
        select=getattr(simulator, "select", None),
        engine_state=engine_state_of(simulator),
    )


def engine_state_of(simulator) -> bool:
    """The ``inputs.engine_state`` hook of the innermost simulator (False when absent): its
    answer is four tensors (:func:`motion_of`), its states the engine's velocities."""
    inputs = getattr(innermost(simulator), "inputs", None)
    return bool(getattr(inputs, "engine_state", False))


def motion_of(out: tuple) -> tuple[tuple[torch.Tensor, torch.Tensor], tuple | None]:
    """A simulator's answer as ``((v_{t+1}, ω_{t+1}), mean)``: ``mean`` the frame's mean motion
    ``(ū, ω̄)`` of a four-tensor answer (the engine state), None for two (the velocities move
    the spheres; :func:`physgnn.physics.integrator.step` takes either)."""
    if len(out) == 4:
        return (out[0], out[1]), (out[2], out[3])
    vel, angvel = out
    return (vel, angvel), None


def innermost(simulator):
    """The simulator at the core of wrappers (each names the one it wraps ``simulator``)."""
    while getattr(simulator, "simulator", None) is not None:
        simulator = simulator.simulator
    return simulator
