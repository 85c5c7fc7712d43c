"""Trajectories in the particle formats of GNS and LagrangeBench, and back.

Both formats hold particle positions and one integer type per particle; a folder holds one
file per split and a ``metadata.json``. Each folder is written whole
(:func:`physgnn.data.exports.staged_folder`). The types follow each reader's conventions:

- GNS (``learning_to_simulate`` / the PyTorch GNS, geoelements/gns ``gns/data_loader.py``):
  ``<split>.npz`` (``train``, ``valid``, ``test``: the names its ``gns/train.py`` opens) with
  one entry ``simulation_trajectory_<i>`` per trajectory, the triple
  ``(positions [T, N, 3] float32, particle_type [N] int64, material_property [N] float32)``
  (a pickled object array: read it with ``allow_pickle=True``). GNS embeds 9 particle types
  and type 3 is its kinematic (fixed) particle, which a sphere never is: material ``k`` is
  type ``GNS_TYPES[k]`` (DeepMind's datasets use 5, 6, 7 for water, sand, goop), so at most 8
  materials. ``material_property`` is each sphere's restitution.
- LagrangeBench (``lagrangebench/data/data.py``): ``<split>.h5`` (splits ``train``,
  ``valid``, ``test``; its runner opens all three) with one group per trajectory (``00000``,
  …) holding ``position [T, N, 3]`` and ``particle_type [N]``, 0 for every sphere:
  LagrangeBench's moving particle (its types 1 and 2 are fixed and moving walls,
  ``lagrangebench/utils.py``). The material id is the extra array ``material [N]`` beside
  them. LagrangeBench reads one length per split (its first trajectory's): a split of
  trajectories of different lengths is refused.

Both take physgnn's split ``val`` as ``valid`` (an export written before as ``val.npz`` still
reads as ``val`` and ``valid``).

``metadata.json`` (strict JSON: trajectories of fewer than 3 frames, which give no
acceleration statistics, are refused): ``dim`` 3, ``dt``, ``bounds`` (per axis, of every
position), ``sequence_length`` (and ``sequence_length_<split>``: the shortest trajectory of
the split), ``default_connectivity_radius`` (three times the largest radius), ``dx`` (the side
of a cube of a sphere's mean volume: LagrangeBench's ``e_kin`` weighs each particle by
``dx**dim``), ``num_particles_max``, ``periodic_boundary_conditions`` (all false),
``write_every`` 1, the statistics of velocity and acceleration in the formats' own units:
position change per frame, and its change per frame (``vel_mean``, ``vel_std``, ``acc_mean``,
``acc_std``, per axis), and physgnn's ``materials`` (``{split: [table [K, 4] per
trajectory]}``, columns ``material_columns``) that the readers below restore. GNS's adds the
input widths its ``gns/train.py`` builds its network with (:func:`gns_widths`): ``nnode_in``,
``nedge_in``.

Reading back needs what the formats drop: the radius (``radius``). See docs/DATA.md.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from physgnn.data.dataset import DatasetError
from physgnn.data.exports import ExportError, staged_folder
from physgnn.physics.scene import Material
from physgnn.physics.trajectory import Trajectory

# The GNS particle type of material 0, 1, ...: GNS's 9 types less its kinematic type 3.
GNS_TYPES = (5, 6, 7, 8, 0, 1, 2, 4)
# geoelements/gns gns/train.py: INPUT_SEQUENCE_LENGTH positions in, particle_type_embedding_size
GNS_INPUT_SEQUENCE_LENGTH = 6
GNS_TYPE_EMBEDDING = 16
LAGRANGEBENCH_MOVING = 0
# physgnn's split names as GNS's train.py and LagrangeBench's runner open them (others kept)
PEER_SPLITS = {"train": "train", "val": "valid", "test": "test"}
MATERIAL_COLUMNS = list(Material.__dataclass_fields__)
# the fewest frames that give metadata.json its acceleration statistics
MIN_FRAMES = 3
DIM = 3


def gns_widths(dim: int = DIM) -> dict:
    """GNS's input widths of a physgnn export, as its ``gns/learned_simulator.py`` builds the
    node and edge features: the last ``INPUT_SEQUENCE_LENGTH - 1`` velocities, the distances
    to the lower and upper bounds, the particle type's embedding and the one
    ``material_property`` each sphere has; edges: the displacement and its length."""
    velocities = (GNS_INPUT_SEQUENCE_LENGTH - 1) * dim
    return {"nnode_in": velocities + 2 * dim + GNS_TYPE_EMBEDDING + 1, "nedge_in": dim + 1}


def check_lengths(fmt: str, splits: dict[str, list[Trajectory]]) -> None:
    """At least one trajectory of :data:`MIN_FRAMES` frames (else metadata.json's statistics
    would be NaN); else :class:`ExportError`."""
    longest = max((t.n_frames for trajs in splits.values() for t in trajs), default=0)
    if longest < MIN_FRAMES:
        raise ExportError(
            f"export to {fmt}: the trajectories hold {longest} frame(s) at most; metadata.json's "
            f"velocity and acceleration statistics need {MIN_FRAMES}: export at least "
            f"{MIN_FRAMES} frames (GNS and LagrangeBench train on windows of "
            f"{GNS_INPUT_SEQUENCE_LENGTH + 1})"
        )


def _write_metadata(path: Path, meta: dict) -> None:
    """``metadata.json`` as strict JSON (a NaN is a bug, never a bare ``NaN`` in the file)."""
    path.write_text(json.dumps(meta, indent=2, allow_nan=False))


def metadata(splits: dict[str, list[Trajectory]]) -> dict:
    """The ``metadata.json`` of ``splits`` (module doc)."""
    trajs = [t for split in splits.values() for t in split]
    pos = np.concatenate([t.pos.reshape(-1, 3) for t in trajs]).astype(np.float64)
    steps = [np.diff(t.pos.astype(np.float64), axis=0) for t in trajs]
    vel = np.concatenate([s.reshape(-1, 3) for s in steps])
    acc = np.concatenate([np.diff(s, axis=0).reshape(-1, 3) for s in steps])
    radii = np.concatenate([t.radius for t in trajs]).astype(np.float64)
    out = {
        "dim": 3,
        "dt": float(trajs[0].dt),
        "solver": "pybullet (physgnn)",
        "bounds": np.stack([pos.min(0), pos.max(0)], axis=1).tolist(),
        "sequence_length": min(t.n_frames for t in trajs),
        "default_connectivity_radius": 3.0 * float(radii.max()),
        "dx": float(np.cbrt(np.mean(4 / 3 * np.pi * radii**3))),
        "num_particles_max": max(t.n_spheres for t in trajs),
        "periodic_boundary_conditions": [False, False, False],
        "write_every": 1,
        "vel_mean": vel.mean(0).tolist(),
        "vel_std": vel.std(0).tolist(),
        "acc_mean": acc.mean(0).tolist(),
        "acc_std": acc.std(0).tolist(),
        "material_columns": MATERIAL_COLUMNS,
        "materials": {k: [t.materials.tolist() for t in v] for k, v in splits.items()},
    }
    for split, items in splits.items():
        out[f"sequence_length_{split}"] = min(t.n_frames for t in items)
    return out


def write_gns(folder: str | Path, splits: dict[str, list[Trajectory]]) -> Path:
    """``<folder>/<split>.npz`` per split (``train``, ``valid`` from ``val``, ``test``; any
    other split keeps its name) and ``metadata.json``; returns the folder."""
    splits = {PEER_SPLITS.get(k, k): v for k, v in splits.items()}
    check_lengths("gns", splits)
    for trajs in splits.values():
        for traj in trajs:
            if traj.material.max(initial=0) >= len(GNS_TYPES):
                raise ExportError(
                    f"export to gns: trajectory '{traj.name}' has material id "
                    f"{int(traj.material.max())}, GNS embeds {len(GNS_TYPES)} moving particle "
                    f"types (0-8 but its kinematic 3): use at most {len(GNS_TYPES)} materials"
                )
    with staged_folder(folder, "gns") as staging:
        for split, trajs in splits.items():
            entries = {f"simulation_trajectory_{i}": _gns_entry(t) for i, t in enumerate(trajs)}
            with open(staging / f"{split}.npz", "wb") as f:
                np.savez_compressed(f, **entries)
        _write_metadata(staging / "metadata.json", metadata(splits) | gns_widths())
    return Path(folder)


def _gns_entry(traj: Trajectory) -> np.ndarray:
    """The triple (positions, particle_type, material_property) as GNS's reader takes it."""
    entry = np.empty(3, dtype=object)
    entry[0] = traj.pos.astype(np.float32)
    entry[1] = np.asarray(GNS_TYPES, np.int64)[traj.material]
    entry[2] = traj.materials[traj.material, 0].astype(np.float32)  # restitution
    return entry


def read_gns(folder: str | Path, split: str, radius: float | np.ndarray) -> list[Trajectory]:
    """The trajectories of ``<folder>/<split>.npz`` with spheres of ``radius`` (one number or
    ``[N]``), ``dt`` and the material tables from ``metadata.json``; orientation and velocities
    as :meth:`~physgnn.physics.trajectory.Trajectory.from_arrays` makes them."""
    folder = Path(folder)
    meta = _metadata(folder)
    path, split = _split_file(folder, split, "npz")
    try:
        with np.load(path, allow_pickle=True) as data:
            names = sorted(data.files, key=lambda k: int(k.rsplit("_", 1)[1]))
            entries = [data[k] for k in names]
        material = [_gns_material(e[1]) for e in entries]
    except Exception as e:  # a truncated zip, another npz, a pickle of something else
        raise _unreadable(path, "gns", e) from None
    tables = _tables(meta, split, len(entries))
    return [
        _from_arrays(path, e[0], radius, meta["dt"], m, table, name)
        for name, e, m, table in zip(names, entries, material, tables, strict=True)
    ]


def _gns_material(types) -> np.ndarray:
    """The material ids ``[N]`` of GNS particle types ``[N]`` (:data:`GNS_TYPES` inverted)."""
    lookup = np.full(max(GNS_TYPES) + 1, -1)
    lookup[list(GNS_TYPES)] = np.arange(len(GNS_TYPES))
    material = lookup[np.broadcast_to(np.asarray(types, np.int64), np.shape(types))]
    if (material < 0).any():
        raise ValueError("particle type 3 is GNS's kinematic (fixed) particle, not a sphere")
    return material


def write_lagrangebench(folder: str | Path, splits: dict[str, list[Trajectory]]) -> Path:
    """``<folder>/{train,valid,test}.h5`` (from the splits ``train``, ``val``, ``test``; any
    other split keeps its name) and ``metadata.json``; returns the folder."""
    named = {PEER_SPLITS.get(k, k): v for k, v in splits.items()}
    check_lengths("lagrangebench", named)
    for split, trajs in named.items():
        lengths = sorted({t.n_frames for t in trajs})
        if len(lengths) > 1:
            raise ExportError(
                f"export to lagrangebench: split {split} holds trajectories of {lengths[0]} "
                f"to {lengths[-1]} frames; LagrangeBench reads one length per split: cut them "
                f"to {lengths[0]} (traj.truncated({lengths[0]})) or export them apart"
            )
    with staged_folder(folder, "lagrangebench") as staging:
        for split, trajs in named.items():
            with h5py.File(staging / f"{split}.h5", "w") as f:
                for i, traj in enumerate(trajs):
                    group = f.create_group(f"{i:05d}")
                    group.create_dataset("position", data=traj.pos.astype(np.float32))
                    moving = np.full(traj.n_spheres, LAGRANGEBENCH_MOVING, np.int64)
                    group.create_dataset("particle_type", data=moving)
                    group.create_dataset("material", data=traj.material.astype(np.int64))
        _write_metadata(staging / "metadata.json", metadata(named))
    return Path(folder)


def read_lagrangebench(
    folder: str | Path, split: str, radius: float | np.ndarray
) -> list[Trajectory]:
    """The trajectories of ``<folder>/<split>.h5`` (``split``: train, valid (or val) or test)
    with spheres of ``radius``, ``dt`` and the material tables from ``metadata.json``."""
    folder = Path(folder)
    meta = _metadata(folder)
    path, split = _split_file(folder, split, "h5")
    try:
        with h5py.File(path, "r") as f:
            keys = sorted(f.keys())
            groups = [(f[k]["position"][()], _lb_material(f[k])) for k in keys]
    except Exception as e:  # a truncated file, not HDF5, groups of another layout
        raise _unreadable(path, "lagrangebench", e) from None
    tables = _tables(meta, split, len(keys))
    return [
        _from_arrays(path, pos, radius, meta["dt"], material, table, key)
        for key, (pos, material), table in zip(keys, groups, tables, strict=True)
    ]


def _lb_material(group) -> np.ndarray:
    """A group's material ids: physgnn's ``material``, else 0 (a LagrangeBench dataset's)."""
    if "material" in group:
        return group["material"][()]
    return np.zeros(len(group["particle_type"]), np.int64)


def _split_file(folder: Path, split: str, suffix: str) -> tuple[Path, str]:
    """The file of ``split`` (physgnn's ``val`` is the peers' ``valid``) and the name it was
    written as: an earlier export's ``val.<suffix>`` where there is no ``valid.<suffix>``."""
    name = PEER_SPLITS.get(split, split)
    path = folder / f"{name}.{suffix}"
    if name == "valid" and not path.exists() and (folder / f"val.{suffix}").exists():
        return folder / f"val.{suffix}", "val"
    return path, name


def _tables(meta: dict, split: str, count: int) -> list:
    """The material tables of ``split`` in ``metadata.json`` (None each where it has none)."""
    return meta.get("materials", {}).get(split, [None] * count)


def _metadata(folder: Path) -> dict:
    """``<folder>/metadata.json`` with its ``dt``; else a one-line :class:`DatasetError`."""
    path = folder / "metadata.json"
    try:
        meta = json.loads(path.read_text())
        meta["dt"] = float(meta["dt"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise _unreadable(path, "metadata", e) from None
    return meta


def _unreadable(path: Path, what: str, err: Exception) -> DatasetError:
    first = (str(err).splitlines() or [""])[0] or type(err).__name__
    return DatasetError(
        f"{path} is missing, truncated or not a {what} file of an export "
        f"({type(err).__name__}: {first}): give the folder physgnn.api.export wrote, whole"
    )


def _from_arrays(path: Path, pos, radius, dt, material, table, name: str) -> Trajectory:
    """:meth:`Trajectory.from_arrays`, its errors naming ``path``."""
    if table is None:  # a dataset not of physgnn: default materials, one per id
        table = np.tile(Material().as_array(), (int(np.max(material, initial=0)) + 1, 1))
    try:
        return Trajectory.from_arrays(
            pos, radius, dt, materials=(np.asarray(table, np.float32), material), name=name
        )
    except ValueError as e:
        raise DatasetError(f"{path}: {e}") from None
