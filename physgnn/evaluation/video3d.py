"""Shaded 3-D videos in perspective: pybullet's software renderer (TinyRenderer, no GPU).

The scene is rebuilt from visual shapes only (nothing collides, nothing is simulated): spheres
of their true radius, one colour per sphere, the ground as a large flat box and each bounded
plane as its box (:func:`physgnn.groundtruth.engine.plane_box_pose`). Each frame places the
spheres and takes one picture from a fixed camera aimed at the middle of the ground truth's
motion. It lives in ``evaluation/`` because it drives pybullet (ground truth) and takes
quaternions as tensors; ``report/`` imports neither.
:func:`render_side_by_side` writes truth (left) and a second trajectory (right) as a GIF, an
MP4 (imageio-ffmpeg's static ffmpeg) and a PNG of the middle frame.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import torch
from PIL import Image, ImageDraw

from physgnn.files import atomic_path
from physgnn.groundtruth.engine import p, plane_box_pose
from physgnn.physics import quaternion as Q
from physgnn.physics.scene import GROUND
from physgnn.physics.trajectory import Trajectory
from physgnn.report.video import frame_indices

WIDTH, HEIGHT = 320, 240  # per side; multiples of 16 for the MP4 encoder


def _colours(n: int) -> np.ndarray:
    import matplotlib

    return matplotlib.colormaps["tab20"](np.arange(n) % 20)


class Renderer:
    """One DIRECT pybullet client holding the visual scene; use as a context manager.

    radius ``[N]``; planes ``[S, 11]``; plane_kind ``[S]``; ``centre`` ``[3]`` and ``extent``
    (m) place the camera."""

    def __init__(self, radius, planes, plane_kind, centre, extent: float):
        self.cid = p.connect(p.DIRECT)
        self.spheres = [
            self._sphere(float(r), c) for r, c in zip(radius, _colours(len(radius)), strict=True)
        ]
        for row, kind in zip(planes, plane_kind, strict=True):
            self._plane(np.asarray(row, np.float64), int(kind), centre, extent)
        distance = 1.4 * extent
        self.view = p.computeViewMatrixFromYawPitchRoll(
            list(centre), distance, 35.0, -30.0, 0.0, 2, physicsClientId=self.cid
        )
        self.proj = p.computeProjectionMatrixFOV(
            50.0, WIDTH / HEIGHT, 0.05, 10 * distance, physicsClientId=self.cid
        )

    def _sphere(self, r: float, colour) -> int:
        shape = p.createVisualShape(
            p.GEOM_SPHERE, radius=r, rgbaColor=list(colour), physicsClientId=self.cid
        )
        return p.createMultiBody(0, -1, shape, physicsClientId=self.cid)

    def _plane(self, row: np.ndarray, kind: int, centre, extent: float) -> None:
        if kind == GROUND:
            half = [2 * extent, 2 * extent, 0.01]
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
        for body, x, q in zip(self.spheres, pos, quat_xyzw, strict=True):
            p.resetBasePositionAndOrientation(
                body, x.tolist(), q.tolist(), physicsClientId=self.cid
            )
        _, _, rgba, _, _ = p.getCameraImage(
            WIDTH, HEIGHT, self.view, self.proj, shadow=1, lightDirection=[0.4, -0.6, 1.0],
            renderer=p.ER_TINY_RENDERER, physicsClientId=self.cid,
        )  # fmt: skip
        return np.asarray(rgba, np.uint8).reshape(HEIGHT, WIDTH, 4)[..., :3]

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        p.disconnect(self.cid)


def camera_target(pos: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre ``[3]`` and extent (m) of the positions ``[T, N, 3]``."""
    pts = pos.reshape(-1, 3)
    lo, hi = pts.min(0) - radius.max(), pts.max(0) + radius.max()
    lo[2] = min(lo[2], 0.0)
    return (lo + hi) / 2, float(max(np.linalg.norm(hi - lo) / 2, 1.0))


def _label(image: np.ndarray, text: str, colour=(0, 0, 0)) -> np.ndarray:
    img = Image.fromarray(image)
    ImageDraw.Draw(img).text((6, 4), text, fill=colour)
    return np.asarray(img)


def render_side_by_side(
    stem: str | Path,
    truth: Trajectory,
    right_pos: np.ndarray,
    quats: tuple[np.ndarray, np.ndarray],
    *,
    right_label: str = "prediction",
    diverged_at: int | None = None,
    max_frames: int = 80,
    fps: float = 10.0,
) -> dict:
    """Write ``stem.gif``, ``stem.mp4`` and ``stem_frame.png``: truth (left) and ``right_pos``
    ``[T', N, 3]`` (right, ``T' ≤ T``, its last frame held); quats (w, x, y, z) ``[T, N, 4]``
    each. Returns the paths by kind."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    xyzw = [Q.to_xyzw(torch.as_tensor(np.asarray(q), dtype=torch.float64)).numpy() for q in quats]
    centre, extent = camera_target(np.asarray(truth.pos), np.asarray(truth.radius))
    images = []
    with Renderer(truth.radius, truth.planes, truth.plane_kind, centre, extent) as r:
        for t in frame_indices(truth.n_frames, max_frames):
            k = min(int(t), len(right_pos) - 1)
            left = _label(
                r.frame(truth.pos[t], xyzw[0][t]), f"ground truth  t = {t * truth.dt:.1f} s"
            )
            stopped = diverged_at is not None and t >= diverged_at
            text = f"{right_label}" + (f"  diverged at step {diverged_at}" if stopped else "")
            right = _label(r.frame(right_pos[k], xyzw[1][min(k, len(xyzw[1]) - 1)]), text,
                           (200, 0, 0) if stopped else (0, 0, 0))  # fmt: skip
            images.append(np.concatenate([left, right], axis=1))
    files = {"gif": stem.with_suffix(".gif"), "png": stem.with_name(stem.name + "_frame.png")}
    with atomic_path(files["gif"], keep_suffix=True) as tmp:
        imageio.mimsave(tmp, images, format="GIF", duration=1000.0 / fps, loop=0)
    with atomic_path(files["png"], keep_suffix=True) as tmp:
        imageio.imwrite(tmp, images[len(images) // 2])
    try:
        files["mp4"] = stem.with_suffix(".mp4")
        with atomic_path(files["mp4"], keep_suffix=True) as tmp:
            imageio.mimsave(tmp, images, format="FFMPEG", fps=fps, macro_block_size=16)
    except (ImportError, ValueError, RuntimeError) as e:  # no ffmpeg: GIF only
        print(f"warning: no MP4 written ({str(e).splitlines()[0]}); the GIF is there")
        files.pop("mp4")
    return {k: str(v) for k, v in files.items()}
