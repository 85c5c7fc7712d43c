"""Shaded 3-D videos in perspective: pybullet's software renderer (TinyRenderer, no GPU).

The scene is rebuilt from visual shapes only (nothing collides, nothing is simulated): spheres
of their true radius, one colour per sphere, the ground as a large flat box and each bounded
plane as its box (:func:`physgnn.groundtruth.bodies.plane_box_pose`). Each frame places the
spheres and takes one picture from a fixed camera aimed at the box where the ground truth's
spheres spend their time (:func:`camera_box`), as close as that box fits the picture; walls
that would stand between the camera and the spheres are left out. It lives in ``evaluation/``
because it drives pybullet (ground truth) and takes quaternions as tensors; ``report/``
imports neither. :func:`render_side_by_side` writes truth (left) and a second trajectory
(right: a prediction, or the truth again) as a GIF, an MP4 (imageio-ffmpeg's static ffmpeg)
and a PNG of the middle frame; ``make eval`` and ``python -m physgnn.simulate`` use it.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import torch
from PIL import Image, ImageDraw

from physgnn.files import atomic_path
from physgnn.groundtruth.bodies import p, plane_box_pose
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import GROUND, WALL
from physgnn.physics.trajectory import Trajectory

WIDTH, HEIGHT = 320, 240  # per side; multiples of 16 for the MP4 encoder
YAW, PITCH, FOV = 35.0, -30.0, 50.0  # camera angles and vertical field of view (degrees)
SHADOW_Z = 0.01  # m, thickness of the discs drawn on the ground under the spheres


def frame_indices(n_frames: int, max_frames: int) -> np.ndarray:
    """At most ``max_frames`` evenly spaced frames, the first and the last included."""
    count = max(1, min(n_frames, max_frames))
    return np.unique(np.linspace(0, n_frames - 1, count).round().astype(int))


def _colours(n: int) -> np.ndarray:
    import matplotlib

    return matplotlib.colormaps["tab20"](np.arange(n) % 20)


class Renderer:
    """One DIRECT pybullet client holding the visual scene; use as a context manager.

    radius ``[N]``; planes ``[S, 11]``; plane_kind ``[S]``; the camera frames the box
    ``lo``, ``hi`` ``[3]`` (:func:`camera_box`)."""

    def __init__(self, radius, planes, plane_kind, lo, hi):
        self.cid = p.connect(p.DIRECT)
        centre = (np.asarray(lo) + np.asarray(hi)) / 2
        distance = fit_distance(self._view(centre, 1.0), lo, hi)
        self.view = self._view(centre, distance)
        self.proj = p.computeProjectionMatrixFOV(
            FOV, WIDTH / HEIGHT, 0.05, 10 * distance, physicsClientId=self.cid
        )
        self.spheres = [
            self._sphere(float(r), c) for r, c in zip(radius, _colours(len(radius)), strict=True)
        ]
        self.shadows = [self._shadow(float(r)) for r in radius]
        eye = camera_position(self.view)
        for row, kind in zip(planes, plane_kind, strict=True):
            row = np.asarray(row, np.float64)
            if int(kind) != WALL or faces(row, eye):
                self._plane(row, int(kind), centre, distance)

    def _view(self, centre, distance: float):
        return p.computeViewMatrixFromYawPitchRoll(
            list(centre), distance, YAW, PITCH, 0.0, 2, physicsClientId=self.cid
        )

    def _sphere(self, r: float, colour) -> int:
        shape = p.createVisualShape(
            p.GEOM_SPHERE, radius=r, rgbaColor=list(colour), physicsClientId=self.cid
        )
        return p.createMultiBody(0, -1, shape, physicsClientId=self.cid)

    def _shadow(self, r: float) -> int:
        """A dark disc on the ground under a sphere (TinyRenderer's own shadows are unusable
        at these scales): it tells a sphere in the air from one on the ground."""
        shape = p.createVisualShape(
            p.GEOM_CYLINDER,
            radius=0.9 * r,
            length=SHADOW_Z,
            rgbaColor=[0.5, 0.48, 0.43, 1],
            physicsClientId=self.cid,
        )
        return p.createMultiBody(0, -1, shape, physicsClientId=self.cid)

    def _plane(self, row: np.ndarray, kind: int, centre, distance: float) -> None:
        if kind == GROUND:
            half = [2 * distance, 2 * distance, 0.01]
            pose = ([float(centre[0]), float(centre[1]), -0.01], [0, 0, 0, 1])
            colour = [0.75, 0.72, 0.65, 1]
        else:
            half, c, quat = plane_box_pose(row, 0.05)
            pose, colour = (c, quat), [0.55, 0.6, 0.7, 1]
        shape = p.createVisualShape(
            p.GEOM_BOX, halfExtents=half, rgbaColor=colour, physicsClientId=self.cid
        )
        p.createMultiBody(0, -1, shape, *pose, physicsClientId=self.cid)

    def frame(self, pos: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
        """One picture ``[HEIGHT, WIDTH, 3]`` uint8 with the spheres at pos ``[N, 3]``."""
        for body, shadow, x, q in zip(self.spheres, self.shadows, pos, quat_xyzw, strict=True):
            p.resetBasePositionAndOrientation(
                body, x.tolist(), q.tolist(), physicsClientId=self.cid
            )
            ground = [float(x[0]), float(x[1]), SHADOW_Z / 2]
            p.resetBasePositionAndOrientation(
                shadow, ground, [0, 0, 0, 1], physicsClientId=self.cid
            )
        _, _, rgba, _, _ = p.getCameraImage(
            WIDTH,
            HEIGHT,
            self.view,
            self.proj,
            shadow=0,
            lightDirection=[0.4, -0.6, 1.0],
            renderer=p.ER_TINY_RENDERER,
            physicsClientId=self.cid,
        )
        return np.asarray(rgba, np.uint8).reshape(HEIGHT, WIDTH, 4)[..., :3]

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        p.disconnect(self.cid)


def camera_position(view) -> np.ndarray:
    """The eye ``[3]`` of a pybullet view matrix (16 numbers, column-major)."""
    m = np.asarray(view, np.float64).reshape(4, 4).T  # world -> camera, row-major
    return -m[:3, :3].T @ m[:3, 3]


def faces(row: np.ndarray, eye: np.ndarray) -> bool:
    """Whether the plane row ``[11]`` shows its front (normal) side to ``eye`` ``[3]``.

    Walls face into the arena: one that turns its back to the camera stands between the
    camera and the spheres, and is left out (a cut-away view)."""
    return float((eye - row[:3]) @ row[3:6]) > 0.0


def camera_box(pos: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box ``lo``, ``hi`` ``[3]`` where the spheres spend their time, pos ``[T, N, 3]``.

    The 5th to 95th percentile of every sphere position of every frame (per axis, grown by
    the largest radius, down to the ground): a short fall from 200 m must not shrink the
    spheres resting below it to dots."""
    pts = pos.reshape(-1, 3)
    lo, hi = np.percentile(pts, 5, axis=0), np.percentile(pts, 95, axis=0)
    lo, hi = lo - radius.max(), hi + radius.max()
    lo[2] = min(lo[2], 0.0)
    return lo, hi


def fit_distance(unit_view, lo, hi, margin: float = 1.1) -> float:
    """The camera distance at which the box ``lo``, ``hi`` ``[3]`` just fits the picture (times
    ``margin``), seen along the view matrix ``unit_view`` (16 numbers, any distance)."""
    m = np.asarray(unit_view, np.float64).reshape(4, 4).T  # rows: right, up, back (to the eye)
    corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T - (lo + hi) / 2
    x, y, back = corners @ m[0, :3], corners @ m[1, :3], corners @ m[2, :3]
    tan_v = np.tan(np.radians(FOV / 2))
    need = back + np.maximum(np.abs(x) / (tan_v * WIDTH / HEIGHT), np.abs(y) / tan_v)
    return float(max(margin * need.max(), 1.0))


def _label(image: np.ndarray, lines: list[tuple[str, tuple]]) -> np.ndarray:
    """``image`` with lines of text ``(text, rgb)`` at its top left."""
    img = Image.fromarray(image)
    draw = ImageDraw.Draw(img)
    for i, (text, colour) in enumerate(lines):
        draw.text((6, 4 + 12 * i), text, fill=colour)
    return np.asarray(img)


def _xyzw(traj: Trajectory) -> np.ndarray:
    return Q.to_xyzw(torch.as_tensor(np.asarray(traj.quat), dtype=torch.float64)).numpy()


def side_by_side_frames(
    truth: Trajectory, panels: list[tuple[Trajectory, str]], title: str, max_frames: int
) -> list[np.ndarray]:
    """Pictures ``[HEIGHT, (1 + P) · WIDTH, 3]``: truth left, then each of the ``P`` panels
    ``(rollout, label)`` (frames ``T' ≤ T``: a diverged rollout's finite prefix, its last frame
    held and its divergence written). A label may hold several lines (``\\n``); ``title`` is
    written under the truth's."""
    qt, qs = _xyzw(truth), [_xyzw(pred) for pred, _ in panels]
    lo, hi = camera_box(np.asarray(truth.pos), np.asarray(truth.radius))
    black, red = (0, 0, 0), (200, 0, 0)
    images = []
    with Renderer(truth.radius, truth.planes, truth.plane_kind, lo, hi) as r:
        for t in frame_indices(truth.n_frames, max_frames):
            left = [(f"ground truth  t = {t * truth.dt:.1f} s", black)]
            if title:
                left.append((title, black))
            row = [_label(r.frame(truth.pos[t], qt[t]), left)]
            for (pred, label), qp in zip(panels, qs, strict=True):
                k = min(int(t), pred.n_frames - 1)
                lines = [(line, black) for line in label.split("\n")]
                if pred.diverged_at is not None and t >= pred.diverged_at:
                    lines.append((f"diverged at step {pred.diverged_at}", red))
                row.append(_label(r.frame(pred.pos[k], qp[k]), lines))
            images.append(np.concatenate(row, axis=1))
    return images


def render_side_by_side(
    stem: str | Path,
    truth: Trajectory,
    panels: list[tuple[Trajectory, str]],
    *,
    title: str = "",
    max_frames: int = 80,
    fps: float = 10.0,
) -> dict:
    """Write ``stem.gif``, ``stem.mp4`` and ``stem_frame.png`` (the middle picture) of
    :func:`side_by_side_frames`; returns the paths by kind (no ``mp4`` without ffmpeg)."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    images = side_by_side_frames(truth, panels, title, max_frames)
    files = {"gif": f"{stem}.gif", "png": f"{stem}_frame.png"}
    with atomic_path(files["gif"], keep_suffix=True) as tmp:
        imageio.mimsave(tmp, images, format="GIF", duration=1000.0 / fps, loop=0)
    with atomic_path(files["png"], keep_suffix=True) as tmp:
        imageio.imwrite(tmp, images[len(images) // 2])
    try:
        with atomic_path(f"{stem}.mp4", keep_suffix=True) as tmp:
            imageio.mimsave(tmp, images, format="FFMPEG", fps=fps, macro_block_size=16)
        files["mp4"] = f"{stem}.mp4"
    except (ImportError, ValueError, RuntimeError) as e:  # no ffmpeg: GIF only
        print(f"warning: no MP4 written ({str(e).splitlines()[0]}); the GIF is there")
    return files
