"""Trajectories in the particle formats of GNS and LagrangeBench, and back.

Both formats hold particle positions and one integer type per particle, nothing else; a
folder holds one file per split and a ``metadata.json`` that both share in spirit:

- GNS (``learning_to_simulate`` / the PyTorch GNS): ``<split>.npz`` with one entry
  ``simulation_trajectory_<i>`` per trajectory, the pair ``(positions [T, N, 3] float32,
  particle_type [N] int64)`` (a pickled object array: read it with ``allow_pickle=True``).
  The particle type is the sphere's material id plus :data:`GNS_TYPE_OFFSET`: GNS treats
  type 3 as kinematic (fixed) particles, which a sphere never is.
- LagrangeBench: ``<split>.h5`` (splits ``train``, ``valid``, ``test``) with one group per
  trajectory (``00000``, …) holding ``position [T, N, 3]`` and ``particle_type [N]`` (the
  material id; LagrangeBench's 0 is its moving fluid particle).

``metadata.json``: ``dim`` 3, ``dt``, ``bounds`` (per axis, of every position),
``sequence_length`` (and LagrangeBench's ``sequence_length_<split>``: the shortest trajectory
of the split), ``default_connectivity_radius`` (three times the largest radius),
``num_particles_max``, ``periodic_boundary_conditions`` (all false) and the statistics of
velocity and acceleration in the formats' own units: position change per frame, and its
change per frame (``vel_mean``, ``vel_std``, ``acc_mean``, ``acc_std``, per axis).

Reading back needs what the formats drop: the radius (``radius``) and, for GNS, ``dt`` is in
the metadata. See docs/DATA.md for what each format cannot hold.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from physgnn.files import atomic_path, write_json
from physgnn.physics.trajectory import Trajectory

GNS_TYPE_OFFSET = 5
LAGRANGEBENCH_SPLITS = {"train": "train", "val": "valid", "test": "test"}


def metadata(splits: dict[str, list[Trajectory]]) -> dict:
    """The ``metadata.json`` of ``splits`` (module doc)."""
    trajs = [t for split in splits.values() for t in split]
    pos = np.concatenate([t.pos.reshape(-1, 3) for t in trajs]).astype(np.float64)
    steps = [np.diff(t.pos.astype(np.float64), axis=0) for t in trajs]
    vel = np.concatenate([s.reshape(-1, 3) for s in steps])
    acc = np.concatenate([np.diff(s, axis=0).reshape(-1, 3) for s in steps])
    out = {
        "dim": 3, "dt": float(trajs[0].dt), "solver": "pybullet (physgnn)",
        "bounds": np.stack([pos.min(0), pos.max(0)], axis=1).tolist(),
        "sequence_length": min(t.n_frames for t in trajs),
        "default_connectivity_radius": 3.0 * max(float(t.radius.max()) for t in trajs),
        "num_particles_max": max(t.n_spheres for t in trajs),
        "periodic_boundary_conditions": [False, False, False], "write_every": 1,
        "vel_mean": vel.mean(0).tolist(), "vel_std": vel.std(0).tolist(),
        "acc_mean": acc.mean(0).tolist(), "acc_std": acc.std(0).tolist(),
    }  # fmt: skip
    for split, items in splits.items():
        out[f"sequence_length_{split}"] = min(t.n_frames for t in items)
    return out


def write_gns(folder: str | Path, splits: dict[str, list[Trajectory]]) -> Path:
    """``<folder>/<split>.npz`` per split and ``metadata.json``; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for split, trajs in splits.items():
        entries = {}
        for i, traj in enumerate(trajs):
            pair = np.empty(2, dtype=object)
            pair[0] = traj.pos.astype(np.float32)
            pair[1] = traj.material.astype(np.int64) + GNS_TYPE_OFFSET
            entries[f"simulation_trajectory_{i}"] = pair
        with atomic_path(folder / f"{split}.npz") as tmp, open(tmp, "wb") as f:
            np.savez_compressed(f, **entries)
    write_json(folder / "metadata.json", metadata(splits))
    return folder


def read_gns(folder: str | Path, split: str, radius: float | np.ndarray) -> list[Trajectory]:
    """The trajectories of ``<folder>/<split>.npz`` with spheres of ``radius`` (one number or
    ``[N]``), ``dt`` from ``metadata.json``; orientation and velocities as
    :meth:`~physgnn.physics.trajectory.Trajectory.from_arrays` makes them."""
    folder = Path(folder)
    dt = json.loads((folder / "metadata.json").read_text())["dt"]
    with np.load(folder / f"{split}.npz", allow_pickle=True) as data:
        names = sorted(data.files, key=lambda k: int(k.rsplit("_", 1)[1]))
        pairs = [data[k] for k in names]
    return [
        Trajectory.from_arrays(pos, radius, dt, material=types - GNS_TYPE_OFFSET, name=name)
        for name, (pos, types) in zip(names, pairs, strict=True)
    ]


def write_lagrangebench(folder: str | Path, splits: dict[str, list[Trajectory]]) -> Path:
    """``<folder>/{train,valid,test}.h5`` (from the splits ``train``, ``val``, ``test``; any
    other split keeps its name) and ``metadata.json``; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    named = {LAGRANGEBENCH_SPLITS.get(k, k): v for k, v in splits.items()}
    for split, trajs in named.items():
        with atomic_path(folder / f"{split}.h5") as tmp, h5py.File(tmp, "w") as f:
            for i, traj in enumerate(trajs):
                group = f.create_group(f"{i:05d}")
                group.create_dataset("position", data=traj.pos.astype(np.float32))
                group.create_dataset("particle_type", data=traj.material.astype(np.int64))
    write_json(folder / "metadata.json", metadata(named))
    return folder


def read_lagrangebench(
    folder: str | Path, split: str, radius: float | np.ndarray
) -> list[Trajectory]:
    """The trajectories of ``<folder>/<split>.h5`` (``split``: train, valid or test) with
    spheres of ``radius``, ``dt`` from ``metadata.json``."""
    folder = Path(folder)
    dt = json.loads((folder / "metadata.json").read_text())["dt"]
    with h5py.File(folder / f"{split}.h5", "r") as f:
        return [
            Trajectory.from_arrays(
                f[k]["position"][()], radius, dt, material=f[k]["particle_type"][()], name=k
            )  # fmt: skip
            for k in sorted(f.keys())
        ]
