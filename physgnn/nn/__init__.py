"""The graph network: tensors in, tensors out (no Lightning, Hydra, scenes or units here)."""

from physgnn.nn.epd import EncodeProcessDecode, ProcessorBlock, Widths
from physgnn.nn.interaction import InteractionBlock
from physgnn.nn.mlp import MLP
from physgnn.nn.surface import SurfaceBlock

__all__ = [
    "MLP",
    "EncodeProcessDecode",
    "InteractionBlock",
    "ProcessorBlock",
    "SurfaceBlock",
    "Widths",
]
