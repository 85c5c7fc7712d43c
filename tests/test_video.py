"""Side-by-side GIF and the OOD energy figure."""

import imageio.v2 as imageio
import numpy as np
import pytest

from physgnn.physics.scene import GROUND, STATIC, WALL, ground_plane, make_plane
from physgnn.report import figures as plots
from physgnn.report import video


def falling(n_frames=30, n=3):
    t = np.arange(n_frames)[:, None] * 0.1
    pos = np.zeros((n_frames, n, 3))
    pos[..., 0] = np.arange(n)[None] * 2.0 + t  # rolling along x at 1 m/s
    pos[..., 2] = np.maximum(5.0 - 0.5 * 9.81 * t**2, 0.5)
    return pos


def test_plane_corners_of_a_tilted_ramp():
    ramp = make_plane((1, 2, 3), (0, 0, 1), (1, 0, 0), 2.0, 0.5)
    corners = video.plane_corners(ramp)
    np.testing.assert_allclose(corners, [[3, 2.5, 3], [-1, 2.5, 3], [-1, 1.5, 3], [3, 1.5, 3]])


@pytest.mark.parametrize(
    "n_frames, max_frames, expected", [(10, 60, 10), (100, 50, 50), (101, 50, 50), (7, 3, 3)]
)
def test_frame_indices_keep_first_and_bound_count(n_frames, max_frames, expected):
    idx = video.frame_indices(n_frames, max_frames)
    assert idx[0] == 0 and len(idx) == expected and idx[-1] == n_frames - 1
    assert np.all(np.diff(idx) > 0)


def test_gif_has_the_expected_frames_and_stays_small(tmp_path):
    truth = falling()
    pred = truth[:12] + 0.2  # a rollout that diverged at step 12 (finite prefix of 12 frames)
    planes = np.stack(
        [
            ground_plane(),
            make_plane((6, 0, 2), (-1, 0, 0), (0, 0, 1), 2, 3),
            make_plane((2, 0, 3), (0.2, 0, 1), (1, 0, -0.2), 1, 1),
        ]
    )
    kinds = np.array([GROUND, WALL, STATIC])
    path = tmp_path / "v.gif"
    n = video.render_gif(
        path, truth, pred, np.full(3, 0.5), planes, kinds, title="t", diverged_at=12, max_frames=15
    )
    frames = imageio.mimread(path)
    assert n == len(frames) == 15
    assert path.stat().st_size < 2_000_000

    # the prediction (right half) freezes after divergence while the truth (left) moves on;
    # the title row changes with the frame counter, GIF palettes add a little noise
    def change(a, b, half):
        w = a.shape[1] // 2
        cols = slice(w, None) if half == "right" else slice(0, w)
        return np.abs(a[40:, cols, :3].astype(float) - b[40:, cols, :3]).mean()

    assert change(frames[-2], frames[-1], "right") < 0.05
    assert change(frames[-2], frames[-1], "left") > 0.5


def test_gif_rejects_mismatched_prediction(tmp_path):
    with pytest.raises(ValueError, match="does not match"):
        video.render_gif(
            tmp_path / "x.gif",
            falling(),
            falling(n=2),
            np.ones(3),
            ground_plane()[None],
            np.array([GROUND]),
        )


def test_energy_figure_is_written(tmp_path):
    series = {
        "ood_cubes": {"ground truth": np.linspace(10, 5, 20), "run": np.ones(8)},
        "ood_spaced_drop": {"ground truth": np.ones(20)},
    }
    path = plots.plot_energy(tmp_path / "e.png", series, {"ood_cubes": 0.1})
    assert path.stat().st_size > 1000
    assert imageio.imread(path).shape[1] > 500
