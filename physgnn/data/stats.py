"""A dataset's normalisation statistics, ``stats.json`` (contract in ARCHITECTURE.md): computed
from the training split's finite-difference velocities (:func:`compute_stats`), written
atomically and read back checked (:func:`write_stats`, :func:`read_stats`), with the engine's
substeps that the split was generated at.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import torch

from physgnn.data.dataset import DatasetError, generate_hint
from physgnn.files import write_json
from physgnn.physics.kinematics import finite_difference_velocities
from physgnn.physics.trajectory import Trajectory

# Std values are floored so that a normaliser never divides by 0.
STD_FLOOR = 1e-6


def _mean_std(x: np.ndarray, axis=0) -> dict:
    return {
        "mean": np.mean(x, axis=axis).tolist(),
        "std": np.maximum(np.std(x, axis=axis), STD_FLOOR).tolist(),
    }


def _float64(a) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.float64))


def compute_stats(trajectories: list[Trajectory]) -> dict:
    """Normalisation statistics (contract in ARCHITECTURE.md) from finite-difference
    velocities; ``n_pairs`` is the number of (frame t, frame t+1) state pairs."""
    if not trajectories:
        raise DatasetError("cannot compute statistics of an empty split")
    vel, angvel, dvel, dangvel, radius, mass = [], [], [], [], [], []
    for tr in trajectories:
        v, w = finite_difference_velocities(
            _float64(tr.pos), _float64(tr.quat), _float64(tr.vel[0]), _float64(tr.angvel[0]), tr.dt
        )
        v, w = v.numpy(), w.numpy()
        vel.append(v.reshape(-1, 3))
        angvel.append(w.reshape(-1, 3))
        dvel.append((v[1:] - v[:-1]).reshape(-1, 3))
        dangvel.append((w[1:] - w[:-1]).reshape(-1, 3))
        radius.append(tr.radius)
        mass.append(tr.mass)
    cat = np.concatenate
    speeds = np.linalg.norm(cat(vel), axis=1)
    r, m = cat(radius).astype(np.float64), cat(mass).astype(np.float64)
    return {
        "vel": _mean_std(cat(vel)),
        "angvel": _mean_std(cat(angvel)),
        "delta_vel": _mean_std(cat(dvel)),
        "delta_angvel": _mean_std(cat(dangvel)),
        "radius": {"mean": float(r.mean()), "std": float(max(r.std(), STD_FLOOR))},
        "mass": {"mean": float(m.mean()), "std": float(max(m.std(), STD_FLOOR))},
        "max_speed": float(speeds.max()),
        "n_pairs": int(sum(tr.n_frames - 1 for tr in trajectories)),
        "substeps": common_substeps(trajectories),
    }


def common_substeps(trajectories: list[Trajectory]) -> int:
    """The engine's substeps per frame that every trajectory was generated at (their
    ``substeps`` attribute), 0 where unknown or not the same for all: what a learned
    simulator's free flight follows (:mod:`physgnn.models.learned`, the engine state)."""
    found = {int(tr.attrs.get("substeps", 0) or 0) for tr in trajectories}
    return found.pop() if len(found) == 1 else 0


def split_substeps(path) -> int:
    """:func:`common_substeps` of a split file, from its groups' attributes alone (for a
    ``stats.json`` written before it held them)."""
    with h5py.File(path, "r") as f:
        found = {int(g.attrs.get("substeps", 0)) for g in f.values() if isinstance(g, h5py.Group)}
    return found.pop() if len(found) == 1 else 0


def write_stats(dataset_dir, stats: dict) -> Path:
    """Write ``stats.json`` atomically into ``dataset_dir``."""
    return write_json(Path(dataset_dir) / "stats.json", stats)


def read_stats(dataset_dir) -> dict:
    """``stats.json`` of a dataset folder, checked for the contract's keys."""
    path = Path(dataset_dir) / "stats.json"
    if not path.exists():
        raise DatasetError(f"{path} not found: {generate_hint(path.parent)}")
    try:
        stats = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path} is not valid JSON ({e})") from None
    keys = ("vel", "angvel", "delta_vel", "delta_angvel", "radius", "mass", "max_speed", "n_pairs")
    missing = [k for k in keys if k not in stats]
    if missing:
        raise DatasetError(f"{path}: missing key(s) {missing}")
    for key in keys[:6]:
        _check_std(path, key, stats[key])
    return stats


def _check_std(path: Path, key: str, entry) -> None:
    """A normaliser divides by ``std``: it must be a positive finite number (or vector)."""
    try:
        std = np.asarray(entry["std"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        std = np.asarray(np.nan)
    if not np.all(np.isfinite(std)) or np.any(std <= 0):
        raise DatasetError(
            f"{path}: {key}.std must be positive and finite (got {np.asarray(std).tolist()}); "
            f"regenerate the dataset ({generate_hint(path.parent)})"
        )
