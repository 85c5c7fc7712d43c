"""The :class:`Simulator` protocol: all that the rollout, the sleeping wrapper and the timer
rely on, in one place.

Required: ``H`` (the model sees the ``H + 1`` latest velocities) and the call
``simulator(state) -> (vel_next [N, 3], angvel_next [N, 3])`` on a batched
:class:`~physgnn.data.state.SceneState`, in physical units. Optional hooks, read once by
:func:`hooks_of` (an absent hook means its default):

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
    )


def innermost(simulator):
    """The simulator at the core of wrappers (each names the one it wraps ``simulator``)."""
    while getattr(simulator, "simulator", None) is not None:
        simulator = simulator.simulator
    return simulator
