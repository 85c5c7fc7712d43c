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


def test_camera_target_ignores_a_short_excursion():
    # 10 spheres resting at z = 0.5 in [0, 9] along x for 100 frames; one of them is 200 m up
    # during the first 3 frames (3 of 1000 positions): the view stays on the resting spheres
    pos = np.zeros((100, 10, 3))
    pos[..., 0], pos[..., 2] = np.arange(10), 0.5
    pos[:3, 0, 2] = 200.0
    centre, extent = V.camera_target(pos, np.full(10, 0.5))
    assert centre[2] < 1.0 and extent < 6.0


def test_walls_before_the_spheres_are_cut_away(monkeypatch):
    # simdata's trajectory: spheres inside 4 walls 10 m wide; any camera outside them sees
    # the spheres only through a cut-away. A frame changes when the spheres are taken away.
    traj = trajectory(n=3, frames=2)
    centre, extent = V.camera_target(traj.pos, traj.radius)
    xyzw = np.tile([0.0, 0.0, 0.0, 1.0], (3, 1))
    away = np.full((3, 3), -100.0)

    def seen(render: V.Renderer) -> float:
        with render as r:
            return float(np.abs(r.frame(traj.pos[0], xyzw) - r.frame(away, xyzw).astype(int)).sum())

    assert seen(V.Renderer(traj.radius, traj.planes, traj.plane_kind, centre, extent)) > 0
    monkeypatch.setattr(V, "faces", lambda row, eye: True)  # every wall drawn: hidden
    assert seen(V.Renderer(traj.radius, traj.planes, traj.plane_kind, centre, extent)) == 0


def test_diverged_prediction_is_held_and_marked():
    truth = trajectory(n=3, frames=12)
    pred = dataclasses.replace(truth, pos=truth.pos[:6] + 0.3, quat=truth.quat[:6], diverged_at=6)
    images = V.side_by_side_frames(truth, pred, "prediction\nrun", "scene", max_frames=12)
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


def test_gif_mp4_and_png_are_written(tmp_path):
    truth = trajectory(n=2, frames=8)
    files = V.render_side_by_side(tmp_path / "v", truth, truth, max_frames=5)
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
