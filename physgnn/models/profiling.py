"""Opt-in timing of simulator steps, kept outside the simulator.

A :class:`StepTimer` given to :func:`physgnn.rollout.rollout` (or used by the bench) splits
each step into graph building, the rest of the simulator call (network, normalisation) and
integration. It watches the simulator's ``graph_builder`` by wrapping it while timing, and
synchronises CUDA at each clock read: a rollout without a timer reads no clock per step.
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import torch

from physgnn.models.protocol import innermost

PARTS = ("graph", "network", "integration")


class _WatchedBuilder:
    """A graph builder that adds its seconds to ``timer.graph`` and its graph's size to
    ``timer.sizes``."""

    def __init__(self, builder, timer: StepTimer):
        self.builder, self.timer = builder, timer

    def __getattr__(self, name):
        if name == "builder":
            raise AttributeError(name)
        return getattr(self.builder, name)

    def __call__(self, state, provisional=()):
        return self.build(state, provisional)[0]

    def build(self, state, provisional=()):
        return self._timed(state, self.builder.build, state, provisional)

    def extend(self, state, basis, provisional):
        return self._timed(state, self.builder.extend, state, basis, provisional)

    def _timed(self, state, build, *args):
        t0 = self.timer.clock(state.pos.device)
        graph, basis = build(*args)
        self.timer.graph += self.timer.clock(state.pos.device) - t0
        self.timer.sizes.append(
            (state.pos.shape[0], graph.pp_index.shape[1], graph.ps_index.shape[1])
        )
        return graph, basis


class StepTimer:
    """Seconds per part of the steps timed (``timings``: graph, network, integration, total
    and the count of steps). ``graph`` is the running total of graph-building seconds and
    ``sizes`` the ``(nodes, pp edges, ps edges)`` of every graph built while watched."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.timings = {"graph": 0.0, "network": 0.0, "integration": 0.0, "total": 0.0, "steps": 0}
        self.graph = 0.0
        self.sizes: list[tuple[int, int, int]] = []

    @staticmethod
    def clock(device: torch.device) -> float:
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        return time.perf_counter()

    @contextmanager
    def watch(self, simulator):
        """Time the graph builder of ``simulator`` (of the simulator it wraps) meanwhile."""
        inner = innermost(simulator)
        builder = getattr(inner, "graph_builder", None)
        if builder is None or isinstance(builder, _WatchedBuilder):
            yield self
            return
        inner.graph_builder = _WatchedBuilder(builder, self)
        try:
            yield self
        finally:
            inner.graph_builder = builder

    def predict(self, simulator, state):
        """``simulator(state)``, its seconds added to graph and network."""
        device = state.pos.device
        t0, g0 = self.clock(device), self.graph
        out = simulator(state)
        graph = self.graph - g0
        self.timings["graph"] += graph
        self.timings["network"] += self.clock(device) - t0 - graph
        return out

    def integrate(self, step, *args, **kwargs):
        """``step(*args, **kwargs)`` (one integration), its seconds added to integration."""
        first = args[0] if args else None
        first = first[0] if isinstance(first, tuple) else first  # a simulator's answer
        device = first.device if torch.is_tensor(first) else torch.device("cpu")
        t0 = self.clock(device)
        out = step(*args, **kwargs)
        self.timings["integration"] += self.clock(device) - t0
        self.timings["steps"] += 1
        return out
