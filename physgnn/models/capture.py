"""A compiled region with a bounded set of input shapes, and a warning when it is exceeded.

``torch.compile`` specialises on the shapes it sees: without dynamic shapes (what CUDA graphs,
``mode="reduce-overhead"``, need) every new (nodes, pp edges, ps edges) shape, grad mode and
train/eval mode compiles anew, and past dynamo's recompile limit it falls back to eager
silently. :func:`compile_in_place` makes a module's ``forward`` (or another of its methods) a
:class:`ShapeBoundCall`, which keeps count instead: the first ``max_shapes`` keys (argument
shapes, grad mode, training flag) run the compiled code, and a later new key runs eager with
one warning naming the fix (pad graphs to buckets, ``model.pad_to_buckets=true``, so that few
shapes occur; or raise the bound). Dynamo's own limit, which counts the compiles of a
code object over every module in the process, is raised to the sum of the bounds, so the
compiled keys are never evicted, however many simulators a process compiles. Parameters stay
the module's: its ``state_dict`` is not changed by compiling.

What a region may hold: with dynamic shapes, any code of tensors whose shapes follow the data
but whose *values* are never read by the host, such as a simulator's whole step after its
graph build (:meth:`~physgnn.models.learned.LearnedSimulator.head`); a graph build itself reads
its edge counts back (or, with fixed capacity, its layout from host ints) and stays outside.
With dynamic shapes the keys are few (argument ranks only); what dynamo still compiles anew
within a key (a size of 0 or 1, an argument that is None or strided differently) counts
against its recompile limit, raised to the bound as well, past which dynamo logs its own
warning.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import torch

MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")


def compile_in_place(module, *args, method: str = "forward", **options) -> None:
    """``module``'s ``method`` compiled from now on, within a bound of shapes
    (:class:`ShapeBoundCall` of ``module, *args, **options``); parameters and ``state_dict``
    unchanged."""
    if not isinstance(getattr(module, method), ShapeBoundCall):
        setattr(module, method, ShapeBoundCall(module, *args, method=method, **options))


def compile_simulator(
    simulator, mode: str = "default", max_shapes: int = 16, cache_dir=None, **options
) -> None:
    """A :class:`~physgnn.models.learned.LearnedSimulator`'s step compiled as two regions with
    dynamic shapes: its graph rules (``graph_builder.rules``) and everything after the graph
    build (``head``); the candidates, the edge-count read-back and the compaction between
    them stay eager. ``cache_dir``: where the compiled code is kept on disk
    (:func:`use_cache_dir`; None: torch's own folder). ``options``: :class:`ShapeBoundCall`'s
    (``backend``)."""
    if cache_dir is not None:
        use_cache_dir(cache_dir)
    compile_in_place(simulator, mode, True, max_shapes, method="head", **options)
    compile_in_place(simulator.graph_builder, mode, True, max_shapes, method="rules", **options)


def use_cache_dir(path) -> Path:
    """Inductor's on-disk caches (compiled graphs, kernels) in ``path`` from now on, for this
    process and the ones it starts (``TORCHINDUCTOR_CACHE_DIR``): a later process compiling the
    same code loads them instead of generating and building it again, so it pays only dynamo's
    tracing (docs/PERFORMANCE.md has the times). torch's default is a folder of the system's
    temp dir, which a reboot may empty."""
    path = Path(path).expanduser().resolve()
    path.mkdir(parents=True, exist_ok=True)
    os.environ["TORCHINDUCTOR_CACHE_DIR"] = str(path)
    return path


def is_compiled(simulator) -> bool:
    """Whether ``simulator``'s step (or that of the simulator a wrapper holds, such as the
    constraint stage's ``simulator``) runs compiled (:func:`compile_simulator`)."""
    inner = getattr(simulator, "simulator", simulator)
    return isinstance(getattr(inner, "head", None), ShapeBoundCall)


def compiled_graphs() -> int:
    """How many graphs dynamo has compiled in this process so far (a compile, or a load from
    the on-disk cache, for a new shape or guard)."""
    return int(torch._dynamo.utils.counters["stats"]["unique_graphs"])


class ShapeBoundCall:
    """``call(*args)``: ``module.<method>(*args)`` through ``torch.compile(method, mode=mode,
    dynamic=dynamic, backend=backend)`` for at most ``max_shapes`` keys (module doc)."""

    bounds = 0  # the sum of every instance's max_shapes in this process

    def __init__(
        self,
        module,
        mode: str = "default",
        dynamic: bool = False,
        max_shapes: int = 16,
        backend: str = "inductor",
        method: str = "forward",
    ):
        if mode not in MODES:
            raise ValueError(f"unknown compile mode '{mode}'; choose one of {list(MODES)}")
        if int(max_shapes) < 1:
            raise ValueError(f"max_shapes must be >= 1, got {max_shapes}")
        self.module, self.max_shapes, self.dynamic = module, int(max_shapes), bool(dynamic)
        self.eager = getattr(module, method)  # the class's method, bound to the module
        options = {"backend": backend, "dynamic": dynamic}
        if backend == "inductor":
            options["mode"] = mode
        if dynamic:  # sizes that happen to be equal (ps edges = spheres) are no guard
            _no_duck_shapes()
        self.compiled = torch.compile(self.eager, **options)
        self.keys: set = set()
        self.warned = False
        # dynamo counts compiles per code object, over every module compiled in the process
        # (a simulator's ``head`` compiled for each of several runs): each call adds its bound
        ShapeBoundCall.bounds += self.max_shapes
        _raise_recompile_limit(ShapeBoundCall.bounds)

    def key(self, args) -> tuple:
        """What a compiled graph is specialised on: the argument shapes (only their ranks with
        dynamic shapes, where one graph serves every size; other arguments by whether they are
        None), grad mode and train/eval mode."""
        size = (lambda a: a.dim()) if self.dynamic else (lambda a: tuple(a.shape))
        shapes = tuple(size(a) if torch.is_tensor(a) else a is None for a in args)
        return shapes, torch.is_grad_enabled(), getattr(self.module, "training", False)

    def __call__(self, *args):
        key = self.key(args)
        if key in self.keys or len(self.keys) < self.max_shapes:
            self.keys.add(key)
            return self.compiled(*args)
        if not self.warned:
            self.warned = True
            warnings.warn(
                f"the compiled code met more than {self.max_shapes} input shapes; new ones "
                "run eager. Pad graphs to buckets (model.pad_to_buckets=true) or raise "
                "lit.compile.shapes",
                stacklevel=2,
            )
        return self.eager(*args)


def _recompile_limit_name() -> str:
    """The name of dynamo's recompile limit in this torch (``cache_size_limit`` before 2.6)."""
    config = torch._dynamo.config
    return "recompile_limit" if hasattr(config, "recompile_limit") else "cache_size_limit"


def recompile_limit() -> int:
    """Dynamo's recompile limit per code object now."""
    return getattr(torch._dynamo.config, _recompile_limit_name())


def _raise_recompile_limit(limit: int) -> None:
    """Dynamo's recompile limit per code object at least ``limit`` (grad and train modes are
    part of the keys already)."""
    setattr(torch._dynamo.config, _recompile_limit_name(), max(recompile_limit(), limit))


def _no_duck_shapes() -> None:
    """Dynamic shapes without "duck sizing": by default two sizes that are equal when traced
    share one symbol, and a later batch where they differ compiles anew (a batch with only
    ground edges has as many ps edges as spheres). Process-wide, as torch keeps it."""
    from torch.fx.experimental import _config as config

    if hasattr(config, "use_duck_shape"):
        config.use_duck_shape = False
