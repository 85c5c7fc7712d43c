"""The training set's normalisation of a learned simulator, kept in its buffers (saved in
checkpoints, so a run folder rebuilds its simulator from the checkpoint alone)."""

from __future__ import annotations

import torch

from physgnn.errors import PhysgnnError

VECTOR_STATS = ("vel", "angvel", "delta_vel", "delta_angvel")
SCALAR_STATS = ("radius", "mass")


class StatsError(PhysgnnError, ValueError):
    """``stats.json`` lacks a field the simulator needs (one-line message)."""


def _stat(stats: dict, key: str, part: str, size: int | None) -> torch.Tensor:
    try:
        value = torch.as_tensor(stats[key][part], dtype=torch.float32)
    except (KeyError, TypeError) as err:
        raise StatsError(
            f"normalisation stats lack '{key}.{part}' (regenerate stats.json)"
        ) from err
    if size is not None and value.shape != (size,):
        raise StatsError(f"stats '{key}.{part}' has shape {tuple(value.shape)}, expected ({size},)")
    return value


def register_stats(module: torch.nn.Module, stats: dict, length_scale: float | None) -> None:
    """Buffers ``<key>_mean`` / ``<key>_std`` of ``stats`` (``[3]`` for the vector statistics,
    scalars for radius and mass) and ``length_scale`` (None: the mean sphere diameter)."""
    for key in VECTOR_STATS:
        module.register_buffer(f"{key}_mean", _stat(stats, key, "mean", 3))
        module.register_buffer(f"{key}_std", _stat(stats, key, "std", 3))
    for key in SCALAR_STATS:
        module.register_buffer(f"{key}_mean", _stat(stats, key, "mean", None).reshape(()))
        module.register_buffer(f"{key}_std", _stat(stats, key, "std", None).reshape(()))
    scale = 2.0 * float(module.radius_mean) if length_scale is None else float(length_scale)
    if not scale > 0:
        raise ValueError(f"length_scale must be > 0 (got {scale})")
    module.register_buffer("length_scale", torch.tensor(scale))


def stats_from_state_dict(state_dict: dict, prefix: str = "") -> dict:
    """The ``stats`` dict stored in a checkpoint's buffers (to rebuild the simulator)."""
    stats = {}
    for key in VECTOR_STATS + SCALAR_STATS:
        stats[key] = {
            part: state_dict[f"{prefix}{key}_{part}"].tolist() for part in ("mean", "std")
        }
    return stats
