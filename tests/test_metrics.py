"""Metrics on hand-computed cases (physgnn.metrics)."""

import dataclasses
import math

import numpy as np
import pytest
from torch.testing import assert_close

from physgnn import metrics as M
from physgnn.metrics import checks
from physgnn.physics.scene import GROUND, STATIC, WALL, Effects, ground_plane, make_plane
from physgnn.physics.trajectory import Trajectory

GROUND_ONLY = (ground_plane()[None], np.array([GROUND]))


def traj_of(pos, radius, mass=None, planes=GROUND_ONLY, dt=0.1, effects=None):
    """A Trajectory with the given frames ``[T, N, 3]`` (identity orientations)."""
    pos = np.asarray(pos, np.float64)
    t, n = pos.shape[:2]
    quat = np.zeros((t, n, 4))
    quat[..., 0] = 1
    vel = np.zeros((t, n, 3))
    vel[1:] = (pos[1:] - pos[:-1]) / dt
    return Trajectory(
        name="hand",
        pos=pos,
        quat=quat,
        vel=vel,
        angvel=np.zeros((t, n, 3)),
        radius=np.asarray(radius, np.float64),
        mass=np.ones(n) if mass is None else np.asarray(mass, np.float64),
        material=np.zeros(n, int),
        planes=planes[0],
        plane_kind=planes[1],
        materials=np.zeros((1, 4)),
        dt=dt,
        effects=effects or Effects(),
    )


def pen(pos, radius, planes=GROUND_ONLY, tol=0.0):
    return M.penetration(np.asarray(pos, float), np.asarray(radius, float), *planes, tol=tol)


# ------------------------------------------------------------------------------ penetration
@pytest.mark.parametrize("brute", [True, False])
def test_two_spheres_overlapping_by_known_depth(monkeypatch, brute):
    if not brute:
        monkeypatch.setattr(checks, "BRUTE_FORCE_MAX", 0)
    # r 1 and 0.5 at distance 1.2: depth 0.3, mean diameter 1.5 -> 0.2; third sphere alone.
    frame = [[0, 0, 10], [1.2, 0, 10], [50, 0, 10]]
    apart = [[0, 0, 10], [3.0, 0, 10], [50, 0, 10]]
    out = pen([apart, frame, frame], [1.0, 0.5, 1.0])
    assert out["depth_sphere"] == pytest.approx(0.2)
    assert out["pct_sphere"] == pytest.approx(200 / 3)
    assert out["depth_ground"] == 0.0 and out["pct_ground"] == 0.0
    assert out["depth_static"] == 0.0 and out["pct_static"] == 0.0


def test_exactly_touching_spheres_do_not_intersect_and_tolerance_filters_the_percentage():
    touching = pen([[[0, 0, 5], [2.0, 0, 5]]], [1.0, 1.0])
    assert touching["pct_sphere"] == 0.0 and touching["depth_sphere"] == 0.0
    frame = [[[0, 0, 5], [1.2, 0, 5]]]  # normalised depth 0.8/2 = 0.4
    assert pen(frame, [1.0, 1.0], tol=0.3)["pct_sphere"] == 100.0
    shallow = pen(frame, [1.0, 1.0], tol=0.5)  # the depth counts, the percentage does not
    assert shallow["pct_sphere"] == 0.0 and shallow["depth_sphere"] == pytest.approx(0.4)
    ground = pen([[[0, 0, 0.45], [3, 0, 0.3]]], [0.5, 0.5], tol=0.1)  # depths 0.05 and 0.2
    assert ground["depth_ground"] == pytest.approx(0.125) and ground["pct_ground"] == 50.0


def test_sphere_sunk_into_ground_by_known_depth():
    # r 0.5 at z 0.4: depth 0.1 / diameter 1 -> 0.1; at z 0.5 it just touches (no intersection).
    # The other sphere tunnelled to z = -0.5: depth 1.0 / diameter 1 -> 1.0.
    out = pen([[[0, 0, 0.5], [5, 0, 3]], [[0, 0, 0.4], [5, 0, -0.5]]], [0.5, 0.5])
    assert out["depth_ground"] == pytest.approx((0.1 + 1.0) / 2)
    assert out["pct_ground"] == 100.0
    out = pen([[[0, 0, 0.5], [5, 0, 3]], [[0, 0, 0.4], [5, 0, 3]]], [0.5, 0.5])
    assert out["depth_ground"] == pytest.approx(0.1) and out["pct_ground"] == 50.0


def test_sphere_crossing_a_bounded_wall_inside_vs_outside_its_extent():
    # Wall in the plane x = 0, |y| <= 2, |z - 5| <= 3 (normal x, reference y, n x d = z).
    wall = make_plane((0, 0, 5), (1, 0, 0), (0, 1, 0), 2.0, 3.0)
    planes = (np.stack([ground_plane(), wall]), np.array([GROUND, WALL]))
    r = 0.5
    inside = pen([[[0.2, 0, 5]]], [r], planes)  # distance 0.2: depth 0.3 / 1
    assert inside["depth_static"] == pytest.approx(0.3) and inside["pct_static"] == 100.0
    # 0.3 beyond the edge, 0.2 off the plane: distance sqrt(0.13) to the edge.
    edge = pen([[[0.2, 2.3, 5]]], [r], planes)
    assert edge["depth_static"] == pytest.approx(0.5 - math.sqrt(0.13))
    far = pen([[[0.2, 10, 5]]], [r], planes)  # crosses the infinite plane, not the wall
    assert far["pct_static"] == 0.0 and far["depth_static"] == 0.0
    # One-sided: a centre 0.1 behind the wall has crossed it (depth r + 0.1, over 0.5 d).
    behind = pen([[[-0.1, 0, 5]]], [r], planes)
    assert behind["depth_static"] == pytest.approx(0.6)
    # Behind the plane but beside the rectangle: the distance to its edge, as in front.
    beside = pen([[[-0.2, 2.3, 5]]], [r], planes)
    assert beside["depth_static"] == pytest.approx(0.5 - math.sqrt(0.13))
    # More than r behind: the far side (of a cube, say), counted as in front: no contact.
    far_behind = pen([[[-0.7, 0, 5]]], [r], planes)
    assert far_behind["pct_static"] == 0.0


def test_static_planes_count_with_walls_and_never_as_ground():
    ramp = make_plane((0, 0, 10), (0, 0, 1), (1, 0, 0), 5.0, 5.0)  # horizontal, in the air
    planes = (np.stack([ground_plane(), ramp]), np.array([GROUND, STATIC]))
    out = pen([[[1, 1, 10.25], [20, 0, 10.25]]], [0.5, 0.5], planes)
    assert out["depth_static"] == pytest.approx(0.25) and out["pct_static"] == 50.0
    assert out["pct_ground"] == 0.0


def test_overlaps_neighbour_query_equals_brute_force(monkeypatch):
    rng = np.random.default_rng(0)
    pos = rng.uniform(0, 6, size=(3, 200, 3))
    radius = rng.uniform(0.2, 0.5, size=200)
    brute = pen(pos, radius)
    monkeypatch.setattr(checks, "BRUTE_FORCE_MAX", 0)
    tree = pen(pos, radius)
    assert brute["pct_sphere"] > 0
    for key in M.PENETRATION_KEYS:
        assert tree[key] == pytest.approx(brute[key], rel=1e-12)


# ----------------------------------------------------------------------------------- energy
def test_energy_series_by_hand():
    # m 2, r 0.5, z 1.5, v (3, 0, 0): 0.5*2*9 + 2*9.81*1.0.
    e = M.energy_series([[[0, 0, 1.5]], [[0, 0, 0.5]]], [[[3, 0, 0]], [[0, 0, 0]]], [2.0], [0.5])
    assert_close(e, np.array([9 + 19.62, 0.0]))


def test_energy_gain_sums_positive_steps_over_initial_energy():
    assert M.energy_gain([10, 8, 9, 12, 11]) == pytest.approx(4 / 10)
    assert M.energy_gain([10, 9, 1]) == 0.0
    assert M.energy_gain([7.0]) == 0.0


def test_energy_rise_is_the_largest_climb_above_the_start():
    assert M.energy_rise([10, 8, 9, 12, 11]) == pytest.approx(2 / 10)
    assert M.energy_rise([10, 9, 1]) == 0.0
    assert M.energy_rise([0.0, 1.0, 0.5], scale=2.0) == pytest.approx(0.5)
    with pytest.raises(M.MetricError, match="NaN or inf at frame 1"):
        M.energy_rise([1.0, math.nan])


def test_zero_initial_energy_divides_by_sum_m_g_r_or_errors():
    assert M.energy_gain([0.0, 1.0, 0.5, 1.5], scale=2.0) == pytest.approx(2.0 / 2.0)
    assert M.energy_gain([-0.1, 0.9], scale=2.0) == pytest.approx(0.5)
    assert M.energy_gain([1e-9, 1.0], scale=2.0) == pytest.approx(0.5)  # float noise is zero
    with pytest.raises(M.MetricError, match="initial energy"):
        M.energy_gain([0.0, 1.0])
    assert M.energy_scale([1.0, 2.0], [0.5, 0.25]) == pytest.approx(9.81 * (0.5 + 0.5))


def test_resting_sphere_has_zero_energy_and_defined_gain():
    traj = traj_of(np.full((5, 1, 3), [0, 0, 0.5]), [0.5])
    out = M.trajectory_metrics(traj)
    assert out["energy_gain"] == 0.0


# --------------------------------------------------------------------------------- accuracy
def test_position_mse_and_mse_at():
    true = np.zeros((3, 2, 3))
    pred = true.copy()
    pred[1, 0] = [3, 4, 0]  # 25 on one sphere of one frame
    assert M.position_mse(pred, true) == pytest.approx(25 / 6)
    assert M.mse_at(pred, true, 1) == pytest.approx(12.5)
    assert M.mse_at(pred, true, 2) == 0.0
    with pytest.raises(M.MetricError, match="frame 3"):
        M.mse_at(pred, true, 3)


def test_chamfer_of_shifted_and_permuted_sets(monkeypatch):
    true = np.array([[[0, 0, 0], [10, 0, 0], [0, 10, 0]]], float)
    assert M.chamfer(true + [0.1, 0, 0], true) == pytest.approx(0.02)
    assert M.chamfer(true[:, ::-1], true) == 0.0
    assert M.position_mse(true[:, ::-1], true) > 0
    # Unequal sets: {0} vs {0, e_x}: 0 + (0 + 1)/2.
    assert M.chamfer([[[0, 0, 0]]], [[[0, 0, 0], [1, 0, 0]]]) == pytest.approx(0.5)
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(4, 150, 3)), rng.normal(size=(4, 120, 3))
    brute = M.chamfer(a, b)
    monkeypatch.setattr(checks, "BRUTE_FORCE_MAX", 0)
    assert M.chamfer(a, b) == pytest.approx(brute, rel=1e-12)


def test_rotation_error_is_the_geodesic_angle():
    ident = np.array([[[1.0, 0, 0, 0]]])
    turned = np.array([[[math.cos(0.15), 0, 0, math.sin(0.15)]]])  # 0.3 rad about z
    assert M.rotation_error(turned, ident) == pytest.approx(0.3, abs=1e-12)
    assert M.rotation_error(-turned, turned) == pytest.approx(0.0, abs=1e-7)


def test_momentum_drift_and_rest_drift_by_hand():
    vel = np.array([[[1, 0, 0], [0, 0, 0]], [[1, 0, 0], [0, 1, 0]]], float)
    assert M.momentum_drift(vel, [1.0, 3.0]) == pytest.approx(3 / 4)
    pos = np.zeros((3, 2, 3))
    pos[2, 0] = [0.1, 0, 0]
    pos[1, 1] = [0, 0, 5]
    assert M.rest_drift(pos, [0.5, 1.0], [True, False]) == pytest.approx(0.2)
    assert M.rest_drift(pos, [0.5, 1.0], [False, False]) is None
    assert M.resting_mask(pos, [0.5, 1.0], tol=0.25).tolist() == [True, False]


# ---------------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "fn, args",
    [
        (M.penetration, (np.zeros((3, 0, 3)), np.zeros(0), *GROUND_ONLY)),
        (M.position_mse, (np.zeros((3, 0, 3)), np.zeros((3, 0, 3)))),
        (M.chamfer, (np.zeros((3, 0, 3)), np.zeros((3, 0, 3)))),
        (M.energy_series, (np.zeros((3, 0, 3)), np.zeros((3, 0, 3)), [], [])),
    ],
)
def test_zero_spheres_is_a_clear_error(fn, args):
    with pytest.raises(M.MetricError, match="no sphere"):
        fn(*args)


def test_nan_rows_are_a_clear_error_naming_the_frame():
    pos = np.ones((4, 2, 3))
    pos[2, 1, 0] = np.nan
    for fn, args in [
        (M.penetration, (pos, [0.5, 0.5], *GROUND_ONLY)),
        (M.position_mse, (pos, np.ones((4, 2, 3)))),
        (M.chamfer, (np.ones((4, 2, 3)), pos)),
        (M.energy_gain, ([1.0, np.inf],)),
    ]:
        with pytest.raises(M.MetricError, match="NaN or inf at frame"):
            fn(*args)
    with pytest.raises(M.MetricError, match="shape"):
        M.position_mse(np.ones((4, 2, 3)), np.ones((3, 2, 3)))


# ------------------------------------------------------------------------ trajectory bundle
def test_trajectory_metrics_of_ground_truth_alone_and_against_a_prediction():
    # One sphere falling 0.5 m per frame for 30 frames, another resting on the ground.
    t = np.arange(30.0)
    pos = np.zeros((30, 2, 3))
    pos[:, 0] = np.stack([np.zeros(30), np.zeros(30), 20 - 0.5 * t], -1)
    pos[:, 1] = [5, 0, 0.5]
    traj = traj_of(pos, [0.5, 0.5], mass=[1.0, 2.0])
    truth = traj
    alone = M.trajectory_metrics(truth)
    assert alone["mse"] is None and alone["chamfer"] is None and alone["mse20"] is None
    assert alone["momentum_drift"] is None  # gravity acts
    assert alone["depth_ground"] == 0.0 and alone["n_frames"] == 30 and alone["n_spheres"] == 2
    # Kinetic energy is constant after frame 1 and potential falls: the only gain is frame 0->1
    # (v_0 = 0 -> 5 m/s): 0.5*1*25 = 12.5 J minus the 0.5 m drop 9.81*0.5.
    e0 = 1 * 9.81 * 19.5
    assert alone["energy_gain"] == pytest.approx((12.5 - 9.81 * 0.5) / e0)

    pred = dataclasses.replace(truth, start=2, vel=truth.vel[:25], diverged_at=25)
    pred.pos = pos[:25].copy()  # truncated (diverged), frames 1.. shifted by 0.1 m
    pred.pos[1:, :, 1] += 0.1
    out = M.trajectory_metrics(pred, traj)
    assert out["mse"] == pytest.approx(0.01 * 24 / 25) and out["mse20"] == pytest.approx(0.01)
    assert out["chamfer"] == pytest.approx(0.02 * 24 / 25)
    assert out["rotation_error"] == 0.0 and out["rest_drift"] == pytest.approx(0.2)
    assert out["diverged_at"] == 25 and out["n_frames"] == 25
    pred.pos, pred.vel = pos[:22], truth.vel[:22]
    assert M.trajectory_metrics(pred, traj)["mse20"] is None  # frame 22 never reached


def test_momentum_drift_only_without_external_force():
    pos = np.zeros((3, 1, 3)) + [0, 0, 5]
    traj = traj_of(pos, [0.5], effects=Effects(gravity=False, surface_contact=False))
    assert M.trajectory_metrics(traj)["momentum_drift"] == 0.0


def test_trajectory_metrics_errors():
    traj = traj_of(np.ones((3, 1, 3)), [0.5])
    pred = traj
    no_scene = dict(radius=None, mass=None, planes=None, plane_kind=None, effects=None)
    with pytest.raises(M.MetricError, match="scene arrays"):
        M.trajectory_metrics(dataclasses.replace(pred, **no_scene))
    with pytest.raises(M.MetricError, match="no 'vel'"):
        M.trajectory_metrics(dataclasses.replace(pred, vel=None), traj)
