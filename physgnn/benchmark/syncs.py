"""What would make a GPU wait: host round trips and kernel launches, counted on any device.

A GPU runs kernels asynchronously; the host stalls whenever it needs a value back
(``.item()``, ``bool(t)``, a size that depends on the data). :class:`DispatchCounter` sees
every aten op of the code it watches (a ``TorchDispatchMode``) and counts

- ``kernels``: every aten op dispatched (about one kernel launch each on a GPU);
- ``syncs``: the ops that read a device value back to the host on CUDA:
  ``_local_scalar_dense`` (``item``, ``float``, ``int``, ``bool`` of a tensor), ``nonzero``,
  boolean-mask indexing and ``masked_select`` (their output size), ``unique`` and
  ``unique_consecutive``, ``bincount`` (its length), ``repeat_interleave`` without
  ``output_size``, ``equal``, ``is_nonzero``; plus ``Tensor.tolist`` and ``Tensor.numpy``,
  which leave the device without an aten op;
- ``copies`` (counted in ``syncs`` too): host data copied to the device, which waits for the
  GPU like a read-back (a pageable copy that is not ``non_blocking``): a tensor made from host
  data (``torch.tensor(list)``, ``new_tensor``, ``as_tensor(array)``: ``lift_fresh``), and a
  copy of a CPU tensor to another device (``_to_copy``, ``copy_``), each counted once. On the
  CPU the first kind is what a CUDA run would copy; 0-dim host scalars are left out (a kernel
  takes them as arguments, no copy).

It runs on the CPU as well, where these ops cost little, which is the point: what a GPU step
would wait for is counted without a GPU. ``where`` names the Python line of each sync
(``record_where=True``), to find them.
"""

from __future__ import annotations

import traceback
from collections import Counter
from contextlib import contextmanager

import torch
from torch.utils._python_dispatch import TorchDispatchMode

aten = torch.ops.aten
_ALWAYS = {
    aten._local_scalar_dense,
    aten.nonzero,
    aten.argwhere,
    aten.masked_select,
    aten._unique,
    aten._unique2,
    aten.unique_dim,
    aten.unique_consecutive,
    aten.unique_dim_consecutive,
    aten.bincount,
    aten.equal,
    aten.is_nonzero,
}
_MASK_INDEXING = {aten.index, aten.index_put, aten.index_put_, aten._index_put_impl_}
_LIFTS = {aten.lift_fresh, aten.lift_fresh_copy}
_COPIES = {aten._to_copy, aten.copy_}


def reads_back(func, args, kwargs) -> bool:
    """True when the aten op ``func`` reads a device value back to the host (module doc)."""
    packet = func.overloadpacket
    if packet in _ALWAYS:
        return True
    if packet is aten.repeat_interleave:
        return func is aten.repeat_interleave.Tensor and kwargs.get("output_size") is None
    if packet in _MASK_INDEXING:
        indices = args[1] if len(args) > 1 else kwargs.get("indices", ())
        return any(
            isinstance(i, torch.Tensor) and i.dtype in (torch.bool, torch.uint8) for i in indices
        )
    return False


def copies_to_device(func, args, kwargs) -> bool:
    """True when the aten op ``func`` copies a CPU tensor to another device and waits for it
    (module doc: ``_to_copy``, ``copy_``, not ``non_blocking``)."""
    if func.overloadpacket not in _COPIES or kwargs.get("non_blocking", False):
        return False
    if func.overloadpacket is aten.copy_:
        target, source = args[0], args[1]
        to = target.device
    else:
        source, to = args[0], kwargs.get("device")
    return (
        isinstance(source, torch.Tensor)
        and source.device.type == "cpu"
        and to is not None
        and torch.device(to).type != "cpu"
    )


class DispatchCounter(TorchDispatchMode):
    """Counts kernels, syncs and copies (module doc) of the code run inside ``with counter:``."""

    def __init__(self, record_where: bool = False):
        super().__init__()
        self.kernels = 0
        self.syncs = 0
        self.copies = 0
        self.record_where = record_where
        self.where: Counter = Counter()
        self._lifted = None  # the last tensor made from host data: its copy is the same one

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        self.kernels += 1
        if reads_back(func, args, kwargs):
            self.count_sync(str(func.overloadpacket.__name__))
        out = func(*args, **kwargs)
        if func.overloadpacket in _LIFTS:
            self._lifted = out
            if out.dim() > 0:
                self.count_copy("host data to tensor")
        elif copies_to_device(func, args, kwargs):
            source = args[1] if func.overloadpacket is aten.copy_ else args[0]
            if source is not self._lifted or source.dim() == 0:
                self.count_copy(f"{func.overloadpacket.__name__} to device")
        return out

    def count_copy(self, what: str) -> None:
        self.copies += 1
        self.count_sync(what)

    def count_sync(self, what: str) -> None:
        self.syncs += 1
        if self.record_where:
            self.where[f"{what} at {_caller()}"] += 1


def _caller() -> str:
    """``file:line`` of the innermost physgnn frame on the stack."""
    for frame in reversed(traceback.extract_stack()):
        if "physgnn" in frame.filename and not frame.filename.endswith("syncs.py"):
            return f"{frame.filename.split('physgnn/')[-1]}:{frame.lineno}"
    return "?"


@contextmanager
def counting(record_where: bool = False):
    """``with counting() as counter:`` counts aten ops and syncs, ``tolist`` and ``numpy``
    included (patched on ``torch.Tensor`` for the duration)."""
    counter = DispatchCounter(record_where)
    originals = {name: getattr(torch.Tensor, name) for name in ("tolist", "numpy")}

    def patched(name):
        def method(self, *args, **kwargs):
            counter.count_sync(name)
            return originals[name](self, *args, **kwargs)

        return method

    for name in originals:
        setattr(torch.Tensor, name, patched(name))
    try:
        with counter:
            yield counter
    finally:
        for name, method in originals.items():
            setattr(torch.Tensor, name, method)


# profiler ranges of code that runs as one compiled region (its ops are not dispatched one by one)
_REGIONS = ("Torch-Compiled Region", "CompiledFunction", "## Call CompiledFxGraph")


class OpsOutsideRegions:
    """``kernels``: the top-level aten ops (not called by another aten op) that ran outside
    compiled regions, read from a ``torch.profiler`` trace: what compiled code still
    dispatches one by one. The dispatch counter cannot see this (dynamo runs eager under a
    dispatch mode)."""

    def __init__(self):
        self.kernels = 0

    def add(self, events) -> None:
        for event in events:
            if event.name.startswith("aten::") and not _inside_op_or_region(event.cpu_parent):
                self.kernels += 1


def _inside_op_or_region(event) -> bool:
    while event is not None:
        if event.name.startswith("aten::") or event.name.startswith(_REGIONS):
            return True
        event = event.cpu_parent
    return False


@contextmanager
def profiling_ops():
    """``with profiling_ops() as ops:`` counts :class:`OpsOutsideRegions` of the code inside."""
    ops = OpsOutsideRegions()
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as trace:
        yield ops
    ops.add(trace.events())
