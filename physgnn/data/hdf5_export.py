"""The hdf5 export (physgnn's dataset schema, one file written whole through
:func:`~physgnn.data.exports.staged_folder`) and the reader of physgnn HDF5 files, which answers
an export folder of another format with that format's reader.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from physgnn.data.dataset import DatasetError, read_split, write_split
from physgnn.data.exports import ExportError, export_marker, staged_folder
from physgnn.physics.trajectory import Trajectory

HDF5_FILE = "trajectories.h5"
# How each format reads back (the advice of load_trajectories given an export).
READERS = {
    "vtk": "physgnn.data.vtk.read_vtk('{folder}')",
    "gns": "physgnn.data.interchange.read_gns('{folder}', 'test', radius)",
    "lagrangebench": "physgnn.data.interchange.read_lagrangebench('{folder}', 'test', radius)",
    "hdf5": f"physgnn.api.load_trajectories('{{folder}}/{HDF5_FILE}')",
}


def write_hdf5(folder: str | Path, trajs: list[Trajectory]) -> Path:
    """``<folder>/trajectories.h5`` in physgnn's dataset schema, written whole; each group
    named as its trajectory (a ``/`` becomes ``_``), unless its ``attrs`` name a group."""
    named = [
        dataclasses.replace(t, attrs={"group": t.name.replace("/", "_")} | t.attrs) for t in trajs
    ]
    _check_groups(named)
    with staged_folder(folder, "hdf5") as staging:
        write_split(staging / HDF5_FILE, named, {"split": "export", "preset": "api"})
    return Path(folder) / HDF5_FILE


def _check_groups(trajs: list[Trajectory]) -> None:
    """Each trajectory's HDF5 group name is one HDF5 takes and reads back, and no two match."""
    seen = {}
    for i, traj in enumerate(trajs):
        group = str(traj.attrs["group"])
        if group in ("", ".", ".."):
            raise ExportError(
                f"export to hdf5: trajectory {i} is named {traj.name!r}, which HDF5 takes as no "
                f"group's name: name it (dataclasses.replace(traj, name='drop'))"
            )
        if group in seen:
            raise ExportError(
                f"export to hdf5: trajectories {seen[group]} and {i} both become the group "
                f"{group!r} ('/' is written '_'): rename one (dataclasses.replace(traj, name=...))"
            )
        seen[group] = i


def load_trajectories(path: str | Path) -> list[Trajectory]:
    """The trajectories of a physgnn HDF5 file (:func:`~physgnn.data.dataset.read_split`);
    an export folder, or a file in one, is answered with the reader of its format."""
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    fmt = export_marker(folder).get("export")
    if fmt and not (fmt == "hdf5" and path.is_file()):
        reader = READERS[fmt].format(folder=folder)
        raise DatasetError(
            f"{path} is a {fmt} export, not a physgnn HDF5 file: read it with {reader}"
        )
    if path.is_dir():
        raise DatasetError(
            f"{path} is a folder: give a physgnn HDF5 file (a dataset's test.h5, "
            f"simulate's simulate.h5, an hdf5 export's {HDF5_FILE})"
        )
    return read_split(path)
