"""A trajectory as VTK files for ParaView, meshio and pyvista, and back.

:func:`write_vtk` writes one folder, whole (:func:`physgnn.data.exports.staged_folder`), its
files XML UnstructuredGrid written by meshio, binary and zlib-compressed:

- ``spheres_00000.vtu``, … one file per frame: a vertex per sphere (its centre) with the point
  arrays ``radius``, ``mass``, ``material``, ``velocity``, ``angular_velocity`` (world frame)
  and ``orientation`` (w, x, y, z);
- ``spheres.vtu.series``: the frames and their times (ParaView opens it as one time series);
- ``planes.vtu``: each plane as a quad, with the cell arrays ``kind`` (0 ground, 1 wall,
  2 static) and ``normal``; the infinite ground is drawn as a square that covers the spheres.

In ParaView: open ``spheres.vtu.series``, then Glyph (Sphere, Scale Array ``radius``, Scale
Factor 2: the glyph sphere's radius is 0.5); open ``planes.vtu`` beside it. In Python:
``meshio.read`` or ``pyvista.read`` of any file. :func:`read_vtk` reads such a folder back
into a :class:`~physgnn.physics.trajectory.Trajectory` (planes rebuilt from their quads).
"""

from __future__ import annotations

import json
from pathlib import Path

import meshio
import numpy as np

from physgnn.data.dataset import DatasetError
from physgnn.data.exports import staged_folder
from physgnn.physics.scene import GROUND, Effects
from physgnn.physics.trajectory import Trajectory

SERIES = "spheres.vtu.series"
PLANES = "planes.vtu"
# (array name, Trajectory field) of each sphere's point data; frame fields per frame
POINT_ARRAYS = (
    ("radius", "radius"),
    ("mass", "mass"),
    ("material", "material"),
    ("velocity", "vel"),
    ("angular_velocity", "angvel"),
    ("orientation", "quat"),
)


def _write(path: Path, points: np.ndarray, cells: tuple[str, np.ndarray], **data) -> None:
    """One .vtu file: ``points [P, 3]``, one block of ``cells`` (meshio's kind, connectivity)
    and ``data`` (``point_data`` or ``cell_data``), binary and zlib-compressed."""
    mesh = meshio.Mesh(np.asarray(points, np.float32), [cells], **data)
    meshio.vtu.write(path, mesh, binary=True, compression="zlib")


def plane_corners(plane: np.ndarray, cover: float) -> np.ndarray:
    """The 4 corners ``[4, 3]`` of a plane row ``[11]``, counter-clockwise about its normal; an
    infinite half length becomes ``cover``."""
    centre, normal, ref = (np.asarray(plane[i : i + 3], np.float64) for i in (0, 3, 6))
    half = [h if np.isfinite(h) else cover for h in np.asarray(plane[9:11], np.float64)]
    other = np.cross(normal, ref)
    signs = ((-1, -1), (1, -1), (1, 1), (-1, 1))
    return np.array([centre + a * half[0] * ref + b * half[1] * other for a, b in signs])


def write_vtk(traj: Trajectory, folder: str | Path) -> Path:
    """Write ``traj`` into ``folder``, replacing an earlier export there whole (module doc);
    returns the series file."""
    vertices = ("vertex", np.arange(traj.n_spheres).reshape(-1, 1))
    files = []
    with staged_folder(folder, "vtk") as staging:
        for k in range(traj.n_frames):
            name = f"spheres_{k:05d}.vtu"
            data = {array: _frame(traj, key, k) for array, key in POINT_ARRAYS}
            _write(staging / name, traj.pos[k], vertices, point_data=data)
            files.append({"name": name, "time": round(k * traj.dt, 9)})
        _write_planes(staging / PLANES, traj)
        series = {"file-series-version": "1.0", "files": files}
        (staging / SERIES).write_text(json.dumps(series, indent=1))
    return Path(folder) / SERIES


def _frame(traj: Trajectory, key: str, k: int) -> np.ndarray:
    values = getattr(traj, key)
    return values[k] if values.ndim > 1 else values


def _write_planes(path: Path, traj: Trajectory) -> None:
    """planes.vtu: one quad per plane row."""
    extent = np.abs(traj.pos[..., :2]).max() if traj.pos.size else 0.0
    cover = 2.0 * float(extent) + 10.0 * float(traj.radius.max(initial=1.0))
    corners = [plane_corners(row, cover) for row in traj.planes]
    points = np.concatenate(corners) if corners else np.zeros((0, 3))
    quads = ("quad", np.arange(4 * len(corners)).reshape(-1, 4))
    cell_data = {"kind": [traj.plane_kind.astype(np.int64)], "normal": [traj.planes[:, 3:6]]}
    _write(path, points, quads, cell_data=cell_data)


def _read(path: Path) -> meshio.Mesh:
    """A .vtu file; a missing, truncated or foreign one is a one-line :class:`DatasetError`."""
    try:
        return meshio.vtu.read(path)
    except Exception as e:  # meshio raises many kinds (ReadError, ParseError, KeyError, ...)
        first = (str(e).splitlines() or [""])[0] or type(e).__name__
        raise DatasetError(
            f"{path} is not a readable VTK file ({first}): give a folder that "
            f"physgnn.api.export(..., 'vtk') wrote, whole"
        ) from None


def read_vtk(folder: str | Path, name: str = "vtk") -> Trajectory:
    """The trajectory :func:`write_vtk` wrote into ``folder``. Effects are the defaults and
    the material table is one default material (VTK holds neither)."""
    folder = Path(folder)
    try:
        files = json.loads((folder / SERIES).read_text())["files"]
        times = [float(f["time"]) for f in files]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise DatasetError(
            f"{folder / SERIES} is missing or not a series file ({type(e).__name__}: {e}): "
            f"give a folder that physgnn.api.export(..., 'vtk') wrote"
        ) from None
    frames = [_read(folder / f["name"]) for f in files]
    dt = times[1] - times[0] if len(files) > 1 else 0.1
    first = frames[0].point_data
    return Trajectory.from_arrays(
        np.stack([f.points for f in frames]),
        first["radius"],
        dt,
        quat=_stacked(frames, "orientation"),
        velocities=(_stacked(frames, "velocity"), _stacked(frames, "angular_velocity")),
        mass=first["mass"],
        materials=(None, first["material"]),  # the default table, each sphere's row
        planes=read_planes(folder / PLANES),
        name=name,
        effects=Effects(),
    )


def _stacked(frames: list, key: str) -> np.ndarray:
    """The point data ``key`` of every frame, ``[T, N, ·]``."""
    return np.stack([f.point_data[key] for f in frames])


def read_planes(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Plane rows ``[S, 11]`` and kinds ``[S]`` rebuilt from the quads of ``planes.vtp``
    (the ground's half lengths infinite again)."""
    mesh = _read(path)
    corners = mesh.points.astype(np.float64).reshape(-1, 4, 3)
    kinds = np.concatenate(mesh.cell_data.get("kind", [np.zeros(0)])).astype(np.int64)
    rows = []
    for quad, kind in zip(corners, kinds, strict=True):
        along, across = quad[1] - quad[0], quad[3] - quad[0]
        half = np.array([np.linalg.norm(along), np.linalg.norm(across)]) / 2
        ref, other = along / (2 * half[0]), across / (2 * half[1])
        if kind == GROUND:
            half[:] = np.inf
        rows.append(np.concatenate([quad.mean(axis=0), np.cross(ref, other), ref, half]))
    return np.array(rows, np.float32).reshape(-1, 11), kinds
