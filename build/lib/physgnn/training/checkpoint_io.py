"""Checkpoints written whole or not at all: :class:`AtomicCheckpointIO` saves each one to a
temporary file beside it, flushes it to disk and renames it over the old one
(:func:`physgnn.files.atomic_path`), so a failed save (a full disk, a kill) leaves the
previous ``last.ckpt`` as it was and never a truncated file under the real name."""

from __future__ import annotations

from typing import Any

import torch
from lightning.pytorch.plugins.io import TorchCheckpointIO

from physgnn.files import atomic_path


class AtomicCheckpointIO(TorchCheckpointIO):
    """Lightning's local checkpoint writer, through a temporary file and a rename."""

    def save_checkpoint(self, checkpoint: dict[str, Any], path, storage_options=None) -> None:
        if storage_options is not None:
            raise TypeError(f"{type(self).__name__} takes no storage_options")
        with atomic_path(path) as tmp:
            torch.save(checkpoint, tmp)
