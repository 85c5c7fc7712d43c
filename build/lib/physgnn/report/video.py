"""Side-by-side GIF of a ground-truth trajectory and a predicted one.

Each side shows two orthographic views: the side view (x–z) above the top view (x–y). Spheres
are circles of their true radius (``EllipseCollection`` in data units, one colour per sphere,
the same on both sides); the ground is a line, walls and ramps are their bounded rectangles
projected onto the view. Frames are subsampled (``stride``) to keep the file small.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import EllipseCollection, PolyCollection  # noqa: E402

from physgnn.files import atomic_path  # noqa: E402
from physgnn.physics.scene import GROUND  # noqa: E402

VIEWS = ((0, 2, "side (x–z)"), (0, 1, "top (x–y)"))


def plane_corners(plane: np.ndarray) -> np.ndarray:
    """The 4 corners ``[4, 3]`` of a bounded plane row ``[11]`` (finite half lengths)."""
    centre, normal, ref = plane[0:3], plane[3:6], plane[6:9]
    other = np.cross(normal, ref)
    hx, hy = plane[9], plane[10]
    signs = ((1, 1), (-1, 1), (-1, -1), (1, -1))
    return np.stack([centre + sx * hx * ref + sy * hy * other for sx, sy in signs])


def frame_indices(n_frames: int, max_frames: int) -> np.ndarray:
    """At most ``max_frames`` evenly spaced frames, the first and the last included."""
    count = max(1, min(n_frames, max_frames))
    return np.unique(np.linspace(0, n_frames - 1, count).round().astype(int))


def view_limits(pos: np.ndarray, radius: np.ndarray, corners: list[np.ndarray]) -> list:
    """Fixed axis limits per view from the ground-truth positions ``[T, N, 3]`` and planes."""
    r = float(radius.max())
    pts = pos.reshape(-1, 3)
    if corners:
        pts = np.concatenate([pts, *corners])
    lo, hi = pts.min(0) - r, pts.max(0) + r
    lo[2] = min(lo[2], 0.0)
    pad = 0.05 * (hi - lo) + r  # per axis: a tall drop must not widen the top view
    lo, hi = lo - pad, hi + pad
    return [((lo[a], hi[a]), (lo[b], hi[b])) for a, b, _ in VIEWS]


def _draw_static(ax, planes, plane_kind, a: int, b: int, lims) -> None:
    (x0, x1), (y0, y1) = lims
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6)
    depth_axis = 3 - a - b  # the axis the view looks along
    faced, edge_on = [], []
    for plane, kind in zip(planes, plane_kind, strict=True):
        if kind == GROUND:
            if b == 2:
                ax.axhline(0.0, color="saddlebrown", lw=1.5)
            continue
        # a plane seen face-on would hide the spheres behind it: outline only
        seen_face_on = abs(plane[3 + depth_axis]) > 0.7
        (edge_on if not seen_face_on else faced).append(plane_corners(plane)[:, [a, b]])
    if edge_on:
        ax.add_collection(PolyCollection(edge_on, facecolor="0.6", edgecolor="0.3", lw=1.0))
    if faced:
        ax.add_collection(
            PolyCollection(faced, facecolor="none", edgecolor="0.5", lw=0.8, linestyle="--")
        )


def _spheres(ax, xy: np.ndarray, radius: np.ndarray, colors) -> EllipseCollection:
    d = 2.0 * radius
    coll = EllipseCollection(
        d,
        d,
        np.zeros_like(d),
        units="xy",
        offsets=xy,
        offset_transform=ax.transData,
        facecolors=colors,
        edgecolors="k",
        linewidths=0.3,
        zorder=3,
    )
    ax.add_collection(coll)
    return coll


def render_gif(
    path: str | Path,
    truth_pos: np.ndarray,
    pred_pos: np.ndarray,
    radius: np.ndarray,
    planes: np.ndarray,
    plane_kind: np.ndarray,
    *,
    title: str = "",
    diverged_at: int | None = None,
    max_frames: int = 60,
    fps: float = 10.0,
    dpi: int = 60,
) -> int:
    """Write a GIF of truth (left) and prediction (right); returns the number of frames.

    truth_pos ``[T, N, 3]``; pred_pos ``[T', N, 3]`` with ``T' ≤ T`` (a diverged rollout is
    shorter: its last finite frame is held and "diverged at step k" is shown).
    """
    truth_pos, pred_pos = np.asarray(truth_pos), np.asarray(pred_pos)
    radius, planes = np.asarray(radius, dtype=np.float64), np.asarray(planes, dtype=np.float64)
    n_frames = truth_pos.shape[0]
    if pred_pos.shape[0] < 1 or pred_pos.shape[1:] != truth_pos.shape[1:]:
        raise ValueError(
            f"prediction shape {pred_pos.shape} does not match truth {truth_pos.shape}"
        )
    fig, colls, counter = _layout(truth_pos, radius, planes, plane_kind, title, dpi)
    background = _background(fig, colls, counter)
    images = []
    for t in frame_indices(n_frames, max_frames):
        fig.canvas.restore_region(background)
        tp = min(int(t), pred_pos.shape[0] - 1)
        for col, a, b, coll in colls:
            src = truth_pos[t] if col == 0 else pred_pos[tp]
            coll.set_offsets(src[:, [a, b]])
            coll.axes.draw_artist(coll)
        stopped = diverged_at is not None and t >= diverged_at
        text = f"{title}   frame {t}/{n_frames - 1}"
        counter.set_text(
            text + (f"   prediction diverged at step {diverged_at}" if stopped else "")
        )
        counter.set_color("red" if stopped else "black")
        fig.draw_artist(counter)
        images.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    with atomic_path(path, keep_suffix=True) as tmp:
        imageio.mimsave(tmp, images, format="GIF", duration=1000.0 / fps, loop=0)
    return len(images)


def _layout(truth_pos, radius, planes, plane_kind, title: str, dpi: int):
    """The figure (truth left, prediction right; side view above top view), the sphere
    collections ``(column, axis a, axis b, collection)`` and the title artist."""
    corners = [plane_corners(p) for p, k in zip(planes, plane_kind, strict=True) if k != GROUND]
    lims = view_limits(truth_pos, radius, corners)
    colors = plt.get_cmap("tab20")(np.arange(truth_pos.shape[1]) % 20)
    fig, axes = plt.subplots(2, 2, figsize=(8, 6.4), dpi=dpi, gridspec_kw={"height_ratios": [1, 1]})
    colls = []
    for col, label in enumerate(("ground truth", "prediction")):
        for row, (a, b, name) in enumerate(VIEWS):
            ax = axes[row, col]
            _draw_static(ax, planes, plane_kind, a, b, lims[row])
            ax.set_title(f"{label}: {name}", fontsize=8)
            colls.append((col, a, b, _spheres(ax, truth_pos[0][:, [a, b]], radius, colors)))
    counter = fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig, colls, counter


def _background(fig, colls, counter):
    """Blitting: the static parts drawn once (spheres and title hidden meanwhile)."""
    counter.set_visible(False)
    for *_, coll in colls:
        coll.set_visible(False)
    fig.canvas.draw()
    background = fig.canvas.copy_from_bbox(fig.bbox)
    counter.set_visible(True)
    for *_, coll in colls:
        coll.set_visible(True)
    return background
