"""A rollout and its ground truth as a Rerun recording (``.rrd``), to scrub through in 3-D.

Optional: it needs the ``rerun`` extra (``pip install -e ".[rerun]"``: ``rerun-sdk``, a large
wheel, so not part of ``make install``); without it :func:`log_rerun` raises
:class:`RerunMissing`, one line saying so. Open the file with ``rerun FILE.rrd``.

What is logged, on the timelines ``frame`` and ``time`` (s):

- ``truth/spheres``: the ground truth, solid spheres (``Ellipsoids3D``: radius, orientation,
  one colour per sphere);
- ``prediction/spheres``: the prediction in the same place and colours, drawn as wireframes,
  so that the gap between a wireframe and its solid sphere is the error (its finite prefix
  when it diverged);
- ``planes``: the bounded planes (walls, ramps) as thin boxes, and the ground; static;
- ``energy/truth``, ``energy/prediction``: total energy (J), each from its own velocities.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from physgnn import metrics
from physgnn.errors import PhysgnnError
from physgnn.groundtruth.bodies import plane_box_pose
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import GROUND
from physgnn.physics.trajectory import Trajectory

INSTALL = 'pip install -e ".[rerun]"'


class RerunMissing(PhysgnnError, ImportError):
    """The optional ``rerun-sdk`` is not installed."""


def require():
    """The ``rerun`` module, or :class:`RerunMissing` (call it before long work)."""
    try:
        import rerun
    except ImportError as e:
        raise RerunMissing(
            f"logging to Rerun needs the optional rerun-sdk: {INSTALL} ({e})"
        ) from None
    return rerun


def _colours(n: int) -> np.ndarray:
    import matplotlib

    return (matplotlib.colormaps["tab20"](np.arange(n) % 20)[:, :3] * 255).astype(np.uint8)


def _spheres(rr, traj: Trajectory, t: int, colours: np.ndarray, fill: str):
    q = Q.to_xyzw(torch.as_tensor(np.asarray(traj.quat[t]), dtype=torch.float64)).numpy()
    return rr.Ellipsoids3D(
        centers=traj.pos[t],
        half_sizes=np.repeat(np.asarray(traj.radius)[:, None], 3, axis=1),
        quaternions=[rr.Quaternion(xyzw=x) for x in q],
        colors=colours,
        fill_mode=fill,
    )


def _planes(rr, planes: np.ndarray, plane_kind: np.ndarray, span: float):
    """Thin boxes of the bounded planes ``[S, 11]``; the ground a ``span`` m square."""
    half, centres, quats = [], [], []
    for row, kind in zip(np.asarray(planes, np.float64), plane_kind, strict=True):
        if int(kind) == GROUND:
            h, c, q = [span, span, 0.005], [0.0, 0.0, -0.005], [0.0, 0.0, 0.0, 1.0]
        else:
            h, c, q = plane_box_pose(row, 0.01)
        half.append(h)
        centres.append(c)
        quats.append(rr.Quaternion(xyzw=q))
    return rr.Boxes3D(half_sizes=half, centers=centres, quaternions=quats, colors=[150, 150, 160])


def log_rerun(path: str | Path, truth: Trajectory, pred: Trajectory | None = None) -> Path:
    """Write ``path`` (``.rrd``): ``truth`` and ``pred`` (optional, frames ``T' ≤ T``)."""
    rr = require()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("physgnn", recording_id=truth.name)
    rec.save(path)
    span = float(np.abs(truth.pos[..., :2]).max() + truth.radius.max() + 1.0)
    rec.log("planes", _planes(rr, truth.planes, truth.plane_kind, span), static=True)
    colours = _colours(truth.n_spheres)
    named = [("truth", truth, "solid")] + ([("prediction", pred, "majorwireframe")] if pred else [])
    for name, traj, fill in named:
        energy = metrics.energy_series(traj.pos, traj.vel, traj.mass, traj.radius)
        for t in range(traj.n_frames):
            rec.set_time("frame", sequence=t)
            rec.set_time("time", duration=t * float(truth.dt))
            rec.log(f"{name}/spheres", _spheres(rr, traj, t, colours, fill))
            rec.log(f"energy/{name}", rr.Scalars(float(energy[t])))
    rec.flush()
    rec.disconnect()
    return path
