"""HDF5 dataset files: one file per split, one group per trajectory (schema in ARCHITECTURE.md).

``write_split`` writes ``path.tmp`` then renames it, so an interrupted run never leaves a half
file under the real name. ``read_split`` checks everything it reads and raises
:class:`DatasetError` with one line naming the problem. Only a folder with the marker file
:data:`DATASET_MARKER` is ever replaced or removed. The folder's ``stats.json``:
:mod:`physgnn.data.stats`.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
from pathlib import Path

import h5py
import numpy as np

from physgnn import CONF_DIR, __version__
from physgnn.errors import PhysgnnError
from physgnn.files import atomic_path, write_json
from physgnn.physics.scene import PLANE_DIM, Effects, SceneError
from physgnn.physics.trajectory import Trajectory

SCHEMA_VERSION = 1
FRAME_FIELDS = ("pos", "quat", "vel", "angvel")
STATIC_FIELDS = ("radius", "mass", "material", "materials", "planes", "plane_kind")
# Written when a trajectory has it; a file without it reads as None (the default planes).
OPTIONAL_FIELDS = ("plane_materials",)
# Chunks hold this many frames of one trajectory (time-major, so a window is one read).
CHUNK_FRAMES = 64
# Written first into every dataset folder physgnn generates: the proof that it may replace it.
DATASET_MARKER = "physgnn-dataset.json"


class DatasetError(PhysgnnError, RuntimeError):
    """A dataset file is missing, corrupt or does not match the schema (one-line message)."""


def _generate_hint(path: Path) -> str:
    return generate_hint(Path(path).parent)


def generate_hint(folder: str | Path, preset: str | None = None) -> str:
    """How to (re)make the dataset folder ``folder``: ``run `make data PRESET=x` or `...``
    when it is where that writes (:func:`default_data_dir` of a preset of conf/data/), else the
    generate command with ``data.dir=`` (``preset``, else the one its marker names, else its
    name when a preset's, else small); with ``overwrite=true`` when it is a dataset (its
    marker: generate replaces no other folder). A folder with files and no marker is not a
    dataset: point data.dir at one, or generate into a new folder."""
    folder = Path(folder)
    preset_file = Path(CONF_DIR) / "data" / f"{folder.name}.yaml"
    preset = preset or dataset_preset(folder) or (folder.name if preset_file.is_file() else "small")
    if folder.is_dir() and any(folder.iterdir()) and not is_dataset(folder):
        return (
            f"{folder} is not a dataset (no {DATASET_MARKER}): point data.dir at a dataset, or "
            f"generate into a new folder (`python -m physgnn.generate data={preset} "
            "data.dir=<a new folder>`)"
        )
    again = " overwrite=true" if is_dataset(folder) else ""
    if preset_file.is_file() and folder.resolve() == default_data_dir(folder.name).resolve():
        make = f"make data PRESET={folder.name}" + (f" ARGS={again.strip()}" if again else "")
        return f"run `{make}` or `python -m physgnn.generate data={folder.name}{again}`"
    return f"run `python -m physgnn.generate data={preset} data.dir={folder}{again}`"


def presets() -> list[str]:
    """The data presets of conf/data/, sorted (``paper``, ``small``, ``tiny``)."""
    return sorted(p.stem for p in (Path(CONF_DIR) / "data").glob("*.yaml"))


def default_data_dir(preset: str) -> Path:
    """Where ``make data PRESET=preset`` writes: ``$PHYSGNN_OUTPUTS`` or outputs, /data/preset."""
    return Path(os.environ.get("PHYSGNN_OUTPUTS") or "outputs") / "data" / preset


def dataset_preset(folder: str | Path) -> str | None:
    """The preset a dataset folder was generated from (its marker), None when unknown."""
    try:
        return str(json.loads((Path(folder) / DATASET_MARKER).read_text())["preset"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def write_marker(folder: str | Path, preset: str) -> Path:
    """Mark ``folder`` (made if needed) as a dataset folder written by physgnn."""
    info = {"physgnn_version": __version__, "schema_version": SCHEMA_VERSION, "preset": preset}
    return write_json(Path(folder) / DATASET_MARKER, info)


def is_dataset(folder: str | Path) -> bool:
    """True when ``folder`` carries physgnn's :data:`DATASET_MARKER`."""
    return (Path(folder) / DATASET_MARKER).is_file()


def _write_traj(group: h5py.Group, traj: Trajectory) -> None:
    t = traj.n_frames
    for key in FRAME_FIELDS:
        arr = np.ascontiguousarray(getattr(traj, key), dtype=np.float32)
        chunk = (min(t, CHUNK_FRAMES), *arr.shape[1:])
        group.create_dataset(key, data=arr, chunks=chunk, compression="gzip", compression_opts=4)
    optional = [k for k in OPTIONAL_FIELDS if getattr(traj, k) is not None]
    for key in (*STATIC_FIELDS, *optional):
        arr = np.asarray(getattr(traj, key))
        dtype = np.int64 if key in ("material", "plane_kind") else np.float32
        group.create_dataset(key, data=arr.astype(dtype))
    attrs = dict(traj.attrs)
    group.attrs["dt"] = float(traj.dt)
    group.attrs["gravity"] = np.asarray(attrs.pop("gravity", (0.0, 0.0, -9.81)), dtype=np.float64)
    group.attrs["scene"] = attrs.pop("scene", traj.name)
    group.attrs["scene_config"] = attrs.pop("scene_config", "")
    group.attrs["effects"] = json.dumps(traj.effects.as_dict())
    group.attrs["seed"] = int(attrs.pop("seed", -1))
    group.attrs["substeps"] = int(attrs.pop("substeps", 0))
    group.attrs["engine"] = str(attrs.pop("engine", ""))
    group.attrs["physgnn_version"] = __version__
    for key, value in attrs.items():  # extra attributes (e.g. engine settings) as JSON
        group.attrs[key] = value if isinstance(value, str) else json.dumps(value)


def write_split(path, trajectories: list[Trajectory], file_attrs: dict) -> Path:
    """Write ``trajectories`` to ``path`` atomically (``path.tmp`` then ``os.replace``).

    Groups are named ``traj_00000``, … unless a trajectory's ``attrs["group"]`` names it.
    ``file_attrs`` should hold ``split`` and ``preset``; ``schema_version`` is added.
    The file is built in memory and written with one plain write: HDF5 writing straight to a
    disk that fills up crashed the process (a segmentation fault in h5py's clean-up), where a
    plain write raises ``OSError(ENOSPC)``, which every command reports in one line.
    """
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs["schema_version"] = SCHEMA_VERSION
        for key, value in file_attrs.items():
            f.attrs[key] = value
        for i, traj in enumerate(trajectories):
            name = traj.attrs.get("group", f"traj_{i:05d}")
            attrs = {k: v for k, v in traj.attrs.items() if k != "group"}
            _write_traj(f.create_group(name), dataclasses.replace(traj, attrs=attrs))
    with atomic_path(path) as tmp:
        tmp.write_bytes(buffer.getbuffer())
    return Path(path)


def _attr(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def _read_traj(path: Path, name: str, g: h5py.Group) -> Trajectory:
    where = f"{path}:{name}"
    missing = [k for k in FRAME_FIELDS + STATIC_FIELDS if k not in g]
    missing += [k for k in ("dt", "effects") if k not in g.attrs]
    if missing:
        raise DatasetError(f"{where}: missing field(s) {missing} (schema v{SCHEMA_VERSION})")
    data = {k: g[k][()] for k in FRAME_FIELDS + STATIC_FIELDS}
    data |= {k: g[k][()] if k in g else None for k in OPTIONAL_FIELDS}
    t, n = data["pos"].shape[:2]
    shapes = {
        "pos": (t, n, 3),
        "quat": (t, n, 4),
        "vel": (t, n, 3),
        "angvel": (t, n, 3),
        "radius": (n,),
        "mass": (n,),
        "material": (n,),
    }
    if data["plane_materials"] is not None:
        shapes["plane_materials"] = (*data["planes"].shape[:1], 4)
    for key, shape in shapes.items():
        if data[key].shape != shape:
            raise DatasetError(f"{where}: {key} has shape {data[key].shape}, expected {shape}")
    if data["planes"].ndim != 2 or data["planes"].shape[1] != PLANE_DIM:
        raise DatasetError(f"{where}: planes has shape {data['planes'].shape}, expected [S, 11]")
    for key in FRAME_FIELDS + ("radius", "mass"):
        if not np.all(np.isfinite(data[key])):
            raise DatasetError(f"{where}: {key} contains NaN or inf")
    for key in ("radius", "mass"):
        if np.any(data[key] <= 0):
            i = int(np.argmin(data[key]))
            raise DatasetError(
                f"{where}: {key} of sphere {i} is {float(data[key][i]):g}; every {key} must be > 0 "
                f"({_generate_hint(path)})"
            )
    try:
        effects = Effects.from_dict(json.loads(_attr(g.attrs["effects"])))
    except (ValueError, SceneError) as e:
        raise DatasetError(f"{where}: bad effects attribute ({e})") from None
    attrs = {k: _attr(v) for k, v in g.attrs.items() if k not in ("dt", "effects")}
    attrs["group"] = name
    return Trajectory(
        name=name,
        dt=float(g.attrs["dt"]),
        effects=effects,
        attrs=attrs,
        **{k: data[k] for k in FRAME_FIELDS + STATIC_FIELDS + OPTIONAL_FIELDS},
    )


def read_split(path) -> list[Trajectory]:
    """All trajectories of a split file, checked (raises :class:`DatasetError`)."""
    path = Path(path)
    if not path.exists():
        raise DatasetError(_missing(path))
    try:
        with h5py.File(path, "r") as f:
            version = f.attrs.get("schema_version")
            if version is None or int(version) != SCHEMA_VERSION:
                raise DatasetError(
                    f"{path} has schema version {version}, this physgnn reads "
                    f"{SCHEMA_VERSION}: regenerate it ({_generate_hint(path)})"
                )
            _check_split(path, f.attrs.get("split"))
            return [_read_traj(path, name, f[name]) for name in sorted(f.keys())]
    except DatasetError:
        raise
    except (OSError, KeyError, ValueError) as e:
        first = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise DatasetError(
            f"{path} is truncated or corrupt ({first}): {_generate_hint(path)}"
        ) from None


SPLIT_FILES = ("train", "val", "test", "ood")  # each names itself in its attribute ``split``


def _missing(path: Path) -> str:
    """What to do about a missing file: a dataset's split is generated; any other is a path
    to check, or a file a command writes (an hdf5 export's, simulate's)."""
    if path.stem in SPLIT_FILES:
        return f"dataset file {path} not found: {_generate_hint(path)}"
    made = {
        "trajectories.h5": f"an hdf5 export writes it: physgnn.api.export(trajs, "
        f"'{path.parent}', 'hdf5')",
        "simulate.h5": f"simulate writes it: python -m physgnn.simulate ... out={path.parent}",
    }
    return f"HDF5 file {path} not found: check the path" + (
        f"; if it is still to be made, {made[path.name]}" if path.name in made else ""
    )


def _check_split(path: Path, split) -> None:
    """A split file whose attribute ``split`` names another split is refused (one line)."""
    split = _attr(split)
    if path.stem in SPLIT_FILES and split is not None and split != path.stem:
        raise DatasetError(
            f"{path} holds the {split} split (its file attribute split={split}), not {path.stem}: "
            f"put the {path.stem} split there ({_generate_hint(path)})"
        )
