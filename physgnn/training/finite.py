"""The training loss must stay finite: checked on the device, read back now and then.

``if not torch.isfinite(loss)`` every step is a host round trip per step on a GPU.
:class:`FiniteWatch` keeps the first non-finite loss of the steps since its last read on the
device and reads it back every ``FINITE_CHECK_EVERY`` steps and at the last batch of an epoch,
before validation or a checkpoint can see the weights that step made. Under DDP every process
reads at the same steps and gathers the others' watches in that read, so a non-finite loss in
one process stops them all with the same error (none is left waiting in a collective).
"""

from __future__ import annotations

import torch
import torch.distributed as dist

from physgnn.errors import PhysgnnError

# Steps between reads of the loss's finiteness (each read is a sync on a GPU).
FINITE_CHECK_EVERY = 10


class NonFiniteLossError(PhysgnnError, RuntimeError):
    """The training loss became NaN or infinite (the model exploded)."""

    exit_code = 1


def processes() -> int:
    """DDP processes of this run (1 without a process group)."""
    return dist.get_world_size() if dist.is_available() and dist.is_initialized() else 1


def first_bad(watch: torch.Tensor) -> tuple[int, float, int]:
    """``(at, value, process)`` of the earliest non-finite loss of every process's ``watch``
    ``[at, value]`` (``at`` -1: none): one read-back, one gather under DDP."""
    world = processes()
    if world == 1:
        at, value = watch.tolist()
        return int(at), value, 0
    parts = [torch.empty_like(watch) for _ in range(world)]
    dist.all_gather(parts, watch)
    found = [(at, rank, value) for rank, (at, value) in enumerate(torch.stack(parts).tolist())]
    at, rank, value = min((f for f in found if f[0] >= 0), default=(-1, 0, 0.0))
    return int(at), value, rank


class FiniteWatch:
    """Raises :class:`NonFiniteLossError` naming the epoch and step of the first non-finite
    loss (and its process under DDP), at the latest ``FINITE_CHECK_EVERY`` steps after it or at
    its epoch's last batch."""

    def __init__(self):
        self.watch: tuple[torch.Tensor, torch.Tensor] | None = None
        self.unchecked: list[tuple[int, int]] = []  # (epoch, step) since the last read

    def update(self, loss: torch.Tensor, epoch: int, step: int, last_batch: bool) -> None:
        first, value = self.watch or (loss.new_full((), -1.0), loss.new_zeros(()))
        loss = loss.detach()
        new = (first < 0) & ~torch.isfinite(loss)
        self.watch = (torch.where(new, len(self.unchecked), first), torch.where(new, loss, value))
        self.unchecked.append((epoch, step))
        if last_batch or len(self.unchecked) >= FINITE_CHECK_EVERY:
            self.read()

    def read(self) -> None:
        at, value, rank = first_bad(torch.stack(self.watch))
        unchecked, self.unchecked, self.watch = self.unchecked, [], None
        if at >= 0:
            epoch, step = unchecked[at]
            world = processes()
            where = f" in DDP process {rank} of {world}" if world > 1 else ""
            raise NonFiniteLossError(
                f"non-finite training loss ({value}) at epoch {epoch}, step {step}{where}: the "
                "model exploded, training stopped"
            )
