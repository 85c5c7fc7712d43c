"""The training loss must stay finite: checked on the device, read back now and then.

``if not torch.isfinite(loss)`` every step is a host round trip per step on a GPU.
:class:`FiniteWatch` keeps the first non-finite loss of the steps since its last read on the
device and reads it back every ``FINITE_CHECK_EVERY`` steps and at the last batch of an epoch,
before validation or a checkpoint can see the weights that step made.
"""

from __future__ import annotations

import torch

from physgnn.errors import PhysgnnError

# Steps between reads of the loss's finiteness (each read is a sync on a GPU).
FINITE_CHECK_EVERY = 10


class NonFiniteLossError(PhysgnnError, RuntimeError):
    """The training loss became NaN or infinite (the model exploded)."""

    exit_code = 1


class FiniteWatch:
    """Raises :class:`NonFiniteLossError` naming the epoch and step of the first non-finite
    loss, at the latest ``FINITE_CHECK_EVERY`` steps after it or at its epoch's last batch."""

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
        at, value = torch.stack(self.watch).tolist()  # the one read-back
        unchecked, self.unchecked, self.watch = self.unchecked, [], None
        if at >= 0:
            epoch, step = unchecked[int(at)]
            raise NonFiniteLossError(
                f"non-finite training loss ({value}) at epoch {epoch}, step {step}: the model "
                "exploded, training stopped"
            )
