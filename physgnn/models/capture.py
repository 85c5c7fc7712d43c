"""A compiled network with a bounded set of input shapes, and a warning when it is exceeded.

``torch.compile`` specialises on the shapes it sees: without dynamic shapes (what CUDA graphs,
``mode="reduce-overhead"``, need) every new (nodes, pp edges, ps edges) shape, grad mode and
train/eval mode compiles anew, and past dynamo's recompile limit it falls back to eager
silently. :func:`compile_in_place` makes a module's ``forward`` a :class:`ShapeBoundCall`,
which keeps count instead: the first ``max_shapes`` keys
(argument shapes, grad mode, training flag) run the compiled network, and a later new key runs
eager with one warning naming the fix (pad graphs to buckets, ``model.pad_to_buckets=true``,
so that few shapes occur; or raise the bound). Dynamo's own limit is raised to the bound, so
the compiled keys are never evicted. Parameters stay the module's: its ``state_dict`` is not
changed by compiling.
"""

from __future__ import annotations

import warnings

import torch
from torch import nn

MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")


def compile_in_place(module: nn.Module, *args, **options) -> None:
    """``module``'s ``forward`` compiled from now on, within a bound of shapes
    (:class:`ShapeBoundCall` of ``module, *args, **options``); parameters and ``state_dict``
    unchanged."""
    if not isinstance(module.forward, ShapeBoundCall):
        module.forward = ShapeBoundCall(module, *args, **options)


class ShapeBoundCall:
    """``call(*args)``: ``module.forward(*args)`` through ``torch.compile(forward, mode=mode,
    dynamic=dynamic, backend=backend)`` for at most ``max_shapes`` keys (module doc)."""

    def __init__(
        self,
        module: nn.Module,
        mode: str = "default",
        dynamic: bool = False,
        max_shapes: int = 16,
        backend: str = "inductor",
    ):
        if mode not in MODES:
            raise ValueError(f"unknown compile mode '{mode}'; choose one of {list(MODES)}")
        if int(max_shapes) < 1:
            raise ValueError(f"max_shapes must be >= 1, got {max_shapes}")
        self.module, self.max_shapes, self.dynamic = module, int(max_shapes), bool(dynamic)
        self.eager = module.forward  # the class's forward, bound to the module
        options = {"backend": backend, "dynamic": dynamic}
        if backend == "inductor":
            options["mode"] = mode
        self.compiled = torch.compile(self.eager, **options)
        self.keys: set = set()
        self.warned = False
        _raise_recompile_limit(self.max_shapes)

    def key(self, args) -> tuple:
        """What a compiled graph is specialised on: the argument shapes (only their ranks with
        dynamic shapes, where one graph serves every size), grad mode and train/eval mode."""
        size = (lambda a: a.dim()) if self.dynamic else (lambda a: tuple(a.shape))
        shapes = tuple(size(a) if torch.is_tensor(a) else a is None for a in args)
        return shapes, torch.is_grad_enabled(), self.module.training

    def __call__(self, *args):
        key = self.key(args)
        if key in self.keys or len(self.keys) < self.max_shapes:
            self.keys.add(key)
            return self.compiled(*args)
        if not self.warned:
            self.warned = True
            warnings.warn(
                f"the compiled network met more than {self.max_shapes} input shapes; new ones "
                "run eager. Pad graphs to buckets (model.pad_to_buckets=true) or raise "
                "lit.compile_shapes",
                stacklevel=2,
            )
        return self.eager(*args)


def _raise_recompile_limit(limit: int) -> None:
    """Dynamo's recompile limit per code object at least ``limit`` (plus grad and train modes,
    which are part of the keys already)."""
    config = torch._dynamo.config
    name = "recompile_limit" if hasattr(config, "recompile_limit") else "cache_size_limit"
    setattr(config, name, max(getattr(config, name), limit))
