"""A trajectory as VTK files for ParaView, and back (XML PolyData, written by hand).

:func:`write_vtk` writes into one folder:

- ``spheres_00000.vtp``, … one file per frame: a point per sphere (its centre) with the point
  arrays ``radius``, ``mass``, ``material``, ``velocity``, ``angular_velocity`` (world frame)
  and ``orientation`` (w, x, y, z);
- ``spheres.vtp.series``: the frames and their times (ParaView opens it as one time series);
- ``planes.vtp``: each plane as a quad, with the cell arrays ``kind`` (0 ground, 1 wall,
  2 static) and ``normal``; the infinite ground is drawn as a square that covers the spheres.

In ParaView: open ``spheres.vtp.series``, then Glyph (Sphere, Scale Array ``radius``, Scale
Factor 2: the glyph sphere's radius is 0.5); open ``planes.vtp`` beside it.
:func:`read_vtk` reads such a folder back into a :class:`~physgnn.physics.trajectory.Trajectory`
(planes rebuilt from their quads).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from physgnn.files import write_text
from physgnn.physics.scene import GROUND, Effects
from physgnn.physics.trajectory import Trajectory

SERIES = "spheres.vtp.series"
PLANES = "planes.vtp"
# (array name, Trajectory field) of each sphere's point data; frame fields per frame
POINT_ARRAYS = (
    ("radius", "radius"), ("mass", "mass"), ("material", "material"), ("velocity", "vel"),
    ("angular_velocity", "angvel"), ("orientation", "quat"),
)  # fmt: skip


def _numbers(values: np.ndarray) -> str:
    """Numbers as text that reads back to the same float32 (9 significant digits)."""
    return " ".join(f"{v:.9g}" for v in np.asarray(values, np.float64).ravel().tolist())


def _array(name: str, values: np.ndarray, components: int) -> str:
    kind = "Int64" if np.issubdtype(np.asarray(values).dtype, np.integer) else "Float32"
    return (f'<DataArray type="{kind}" Name="{name}" NumberOfComponents="{components}" '
            f'format="ascii">{_numbers(values)}</DataArray>')  # fmt: skip


def _polydata(points: np.ndarray, kind: str, cells: int, body: str) -> str:
    """One XML PolyData file: points ``[P, 3]``, ``cells`` cells of ``kind`` (Verts or
    Polys) and ``body``: the cells' connectivity and the point and cell data, as text."""
    counts = {k: (cells if k == kind else 0) for k in ("Verts", "Polys")}
    return (
        '<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0" '
        'byte_order="LittleEndian">\n<PolyData>\n'
        f'<Piece NumberOfPoints="{len(points)}" NumberOfVerts="{counts["Verts"]}" '
        f'NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="{counts["Polys"]}">\n'
        f"{body}\n<Points>{_array('points', points, 3)}</Points>\n"
        "</Piece>\n</PolyData>\n</VTKFile>\n"
    )


def _cells(kind: str, connectivity: np.ndarray, offsets: np.ndarray) -> str:
    return (f"<{kind}>{_array('connectivity', connectivity, 1)}"
            f"{_array('offsets', offsets, 1)}</{kind}>\n")  # fmt: skip


def plane_corners(plane: np.ndarray, cover: float) -> np.ndarray:
    """The 4 corners ``[4, 3]`` of a plane row ``[11]``, counter-clockwise about its normal; an
    infinite half length becomes ``cover``."""
    centre, normal, ref = (np.asarray(plane[i : i + 3], np.float64) for i in (0, 3, 6))
    half = [h if np.isfinite(h) else cover for h in np.asarray(plane[9:11], np.float64)]
    other = np.cross(normal, ref)
    signs = ((-1, -1), (1, -1), (1, 1), (-1, 1))
    return np.array([centre + a * half[0] * ref + b * half[1] * other for a, b in signs])


def write_vtk(traj: Trajectory, folder: str | Path) -> Path:
    """Write ``traj`` into ``folder`` (module doc); returns the series file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    n = traj.n_spheres
    verts = _cells("Verts", np.arange(n), np.arange(1, n + 1))
    files = []
    for k in range(traj.n_frames):
        data = "".join(_frame_array(traj, name, key, k) for name, key in POINT_ARRAYS)
        name = f"spheres_{k:05d}.vtp"
        body = f"{verts}<PointData>{data}</PointData>"
        write_text(folder / name, _polydata(traj.pos[k], "Verts", n, body))
        files.append({"name": name, "time": round(k * traj.dt, 9)})
    write_text(folder / PLANES, _planes(traj))
    series = {"file-series-version": "1.0", "files": files}
    return write_text(folder / SERIES, json.dumps(series, indent=1))


def _frame_array(traj: Trajectory, name: str, key: str, k: int) -> str:
    values = getattr(traj, key)
    values = values[k] if values.ndim > 1 else values
    return _array(name, values, 1 if values.ndim == 1 else values.shape[-1])


def _planes(traj: Trajectory) -> str:
    """planes.vtp: one quad per plane row."""
    extent = np.abs(traj.pos[..., :2]).max() if traj.pos.size else 0.0
    cover = 2.0 * float(extent) + 10.0 * float(traj.radius.max(initial=1.0))
    corners = [plane_corners(row, cover) for row in traj.planes]
    points = np.concatenate(corners) if corners else np.zeros((0, 3))
    s = len(corners)
    polys = _cells("Polys", np.arange(4 * s), 4 * np.arange(1, s + 1))
    cell_data = _array("kind", traj.plane_kind.astype(np.int64), 1)
    cell_data += _array("normal", traj.planes[:, 3:6], 3)
    return _polydata(points, "Polys", s, f"{polys}<CellData>{cell_data}</CellData>")


def _read_arrays(path: Path) -> dict[str, np.ndarray]:
    """Every DataArray of a .vtp file by name (points as ``points``)."""
    arrays = {}
    for node in ET.parse(path).getroot().iter("DataArray"):
        dtype = np.int64 if node.get("type") == "Int64" else np.float32
        values = np.array((node.text or "").split(), dtype=np.float64).astype(dtype)
        parts = int(node.get("NumberOfComponents", "1"))
        arrays[node.get("Name")] = values.reshape(-1, parts) if parts > 1 else values
    return arrays


def read_vtk(folder: str | Path, name: str = "vtk") -> Trajectory:
    """The trajectory :func:`write_vtk` wrote into ``folder``. Effects are the defaults and
    the material table is one default material (VTK holds neither)."""
    folder = Path(folder)
    files = json.loads((folder / SERIES).read_text())["files"]
    frames = [_read_arrays(folder / f["name"]) for f in files]
    dt = files[1]["time"] - files[0]["time"] if len(files) > 1 else 0.1
    stack = lambda key: np.stack([f[key] for f in frames])  # noqa: E731
    planes, kinds = read_planes(folder / PLANES)
    return Trajectory.from_arrays(
        stack("points"), frames[0]["radius"], dt, quat=stack("orientation"),
        vel=stack("velocity"), angvel=stack("angular_velocity"), mass=frames[0]["mass"],
        material=frames[0]["material"], planes=planes, plane_kind=kinds, name=name,
        effects=Effects(),
    )  # fmt: skip


def read_planes(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Plane rows ``[S, 11]`` and kinds ``[S]`` rebuilt from the quads of ``planes.vtp``
    (the ground's half lengths infinite again)."""
    arrays = _read_arrays(path)
    corners = arrays["points"].astype(np.float64).reshape(-1, 4, 3)
    kinds = arrays["kind"].astype(np.int64)
    rows = []
    for quad, kind in zip(corners, kinds, strict=True):
        along, across = quad[1] - quad[0], quad[3] - quad[0]
        half = np.array([np.linalg.norm(along), np.linalg.norm(across)]) / 2
        ref, other = along / (2 * half[0]), across / (2 * half[1])
        if kind == GROUND:
            half[:] = np.inf
        rows.append(np.concatenate([quad.mean(axis=0), np.cross(ref, other), ref, half]))
    return np.array(rows, np.float32).reshape(-1, 11), kinds
