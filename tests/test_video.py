"""The shaded 3-D side-by-side video (evaluation.video3d) and the OOD energy figure."""

import dataclasses

import imageio.v2 as imageio
import numpy as np
import pybullet as p
import pytest
from simdata import trajectory

from physgnn.evaluation import video3d as V
from physgnn.physics.scene import make_plane
from physgnn.report import figures as plots


@pytest.mark.parametrize(
    "n_frames, max_frames, expected", [(10, 60, 10), (100, 50, 50), (101, 50, 50), (7, 3, 3)]
)
def test_frame_indices_keep_first_and_bound_count(n_frames, max_frames, expected):
    idx = V.frame_indices(n_frames, max_frames)
    assert idx[0] == 0 and len(idx) == expected and idx[-1] == n_frames - 1
    assert np.all(np.diff(idx) > 0)


def test_camera_position_inverts_the_view_matrix():
    view = p.computeViewMatrix([3.0, 4.0, 5.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(V.camera_position(view), [3, 4, 5], atol=1e-5)


def test_a_wall_faces_the_camera_only_from_its_inner_side():
    wall = make_plane((5, 0, 2), (-1, 0, 0), (0, 1, 0), 5, 2)  # at x = 5, facing -x
    assert V.faces(wall, np.array([0.0, -20.0, 10.0]))  # camera inside its half space
    assert not V.faces(wall, np.array([20.0, 0.0, 10.0]))  # behind it: it would hide all


def test_camera_box_ignores_a_short_excursion():
    # 10 spheres resting at z = 0.5 in [0, 9] along x for 100 frames; one of them is 200 m up
    # during the first 3 frames (3 of 1000 positions): the view stays on the resting spheres
    pos = np.zeros((100, 10, 3))
    pos[..., 0], pos[..., 2] = np.arange(10), 0.5
    pos[:3, 0, 2] = 200.0
    lo, hi = V.camera_box(pos, np.full(10, 0.5))
    np.testing.assert_allclose(lo, [-0.5, -0.5, 0.0])
    np.testing.assert_allclose(hi, [9.5, 0.5, 1.0])


def ndc(view, point, distance: float) -> np.ndarray:
    """Normalised device coordinates (x, y) of ``point`` seen by the renderer's camera."""
    proj = np.asarray(p.computeProjectionMatrixFOV(V.FOV, V.WIDTH / V.HEIGHT, 0.05, 10 * distance))
    clip = proj.reshape(4, 4).T @ np.asarray(view).reshape(4, 4).T @ np.append(point, 1.0)
    return clip[:2] / clip[3]


@pytest.mark.parametrize("hi", [(10.0, 2.0, 1.0), (1.0, 1.0, 30.0), (4.0, 6.0, 3.0)])
def test_fit_distance_frames_the_box_just(hi):
    lo, hi = np.zeros(3), np.asarray(hi)
    centre = (lo + hi) / 2
    unit = p.computeViewMatrixFromYawPitchRoll(centre.tolist(), 1.0, V.YAW, V.PITCH, 0.0, 2)
    d = V.fit_distance(unit, lo, hi, margin=1.0)
    corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T

    def widest(distance):
        view = p.computeViewMatrixFromYawPitchRoll(centre.tolist(), distance, V.YAW, V.PITCH, 0, 2)
        return max(np.abs(ndc(view, c, distance)).max() for c in corners)

    assert widest(d) == pytest.approx(1.0, abs=1e-4)  # a corner on the picture's edge
    assert widest(1.1 * d) < 1.0 < widest(0.9 * d)


def test_diverged_prediction_is_held_and_marked():
    truth = trajectory(n=3, frames=12)
    pred = dataclasses.replace(truth, pos=truth.pos[:6] + 0.3, quat=truth.quat[:6], diverged_at=6)
    images = V.side_by_side_frames(truth, [(pred, "prediction\nrun")], "scene", max_frames=12)
    assert len(images) == 12 and images[0].shape == (V.HEIGHT, 2 * V.WIDTH, 3)
    left, right = slice(0, V.WIDTH), slice(V.WIDTH, None)
    below_text = slice(40, None)

    def change(a, b, half):
        return np.abs(a[below_text, half].astype(int) - b[below_text, half]).sum()

    # frames 5 and 6 show the same (last finite) prediction; 6 adds the red divergence line
    assert change(images[5], images[6], right) == 0 and change(images[-2], images[-1], right) == 0
    assert change(images[-2], images[-1], left) > 0  # the truth moves on
    labels = images[6][:40, right].astype(int) - images[5][:40, right]
    assert (labels != 0).any() and (labels[..., 1:] <= 0).all()  # red text added


def test_every_panel_is_drawn_beside_the_truth():
    truth = trajectory(n=3, frames=6)
    moved = dataclasses.replace(truth, pos=truth.pos + 0.5)
    images = V.side_by_side_frames(truth, [(truth, "a"), (moved, "b")], "", max_frames=6)
    assert images[0].shape == (V.HEIGHT, 3 * V.WIDTH, 3)
    below_text = slice(40, None)
    left, middle, right = (images[3][below_text, k * V.WIDTH : (k + 1) * V.WIDTH] for k in range(3))
    assert np.array_equal(left, middle) and not np.array_equal(middle, right)


def test_gif_mp4_and_png_are_written(tmp_path):
    truth = trajectory(n=2, frames=8)
    files = V.render_side_by_side(tmp_path / "v", truth, [(truth, "truth")], max_frames=5)
    assert sorted(files) == ["gif", "mp4", "png"]
    assert len(imageio.mimread(files["gif"])) == 5
    assert imageio.imread(files["png"]).shape == (V.HEIGHT, 2 * V.WIDTH, 3)
    with imageio.get_reader(files["mp4"]) as reader:
        assert reader.count_frames() == 5


def test_energy_figure_is_written(tmp_path):
    series = {
        "ood_cubes": {"ground truth": np.linspace(10, 5, 20), "run": np.ones(8)},
        "ood_spaced_drop": {"ground truth": np.ones(20)},
    }
    path = plots.plot_energy(tmp_path / "e.png", series, {"ood_cubes": 0.1})
    assert path.stat().st_size > 1000
    assert imageio.imread(path).shape[1] > 500
