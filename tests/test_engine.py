"""pybullet ground truth against analytic physics (physgnn.groundtruth.engine)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from truthkit import DT, G, flight_apexes, spheres

from physgnn.groundtruth.engine import as_stored, simulate
from physgnn.groundtruth.settings import EngineSettings
from physgnn.physics import quaternion as Q
from physgnn.physics.kinematics import finite_difference_velocities
from physgnn.physics.scene import Effects, SceneError

SUBSTEPS = EngineSettings().substeps
H = DT / SUBSTEPS  # physics step


def test_the_start_simulated_is_the_start_stored():
    """pybullet hands back another quaternion than it was given (normalised, its sign its
    own), so a scene is simulated from :func:`as_stored`: the trajectory's frame 0 is then
    exactly the start simulated, and rounding it again changes nothing."""
    quat = [[-0.6, 0.8, 0.0, 0.0], [0.5, 0.5, 0.5, 0.5000001]]
    scene = spheres([[0, 0, 2], [3, 0, 2]], vel=[[1, 0, 0], [0, 0.3, 0]], quat=quat, n_frames=3)
    assert not np.array_equal(simulate(scene).quat[0], scene.quat)
    stored = as_stored(scene)
    traj = simulate(stored)
    for key in ("pos", "quat", "vel", "angvel"):
        np.testing.assert_array_equal(getattr(traj, key)[0], getattr(stored, key))
        np.testing.assert_array_equal(getattr(as_stored(stored), key), getattr(stored, key))


def test_free_fall_matches_analytic_and_discrete_formulas():
    z0 = 20.0
    traj = simulate(spheres([0, 0, z0], n_frames=15))  # lands after 1.96 s: 14 frames in flight
    t = np.arange(15) * DT
    n = np.arange(15) * SUBSTEPS
    # Semi-implicit Euler with step h: z_n = z0 − g·h²·n(n+1)/2 = z0 − g t²/2 − g·h·t/2.
    discrete = z0 - G * H**2 * n * (n + 1) / 2
    np.testing.assert_allclose(traj.pos[:, 0, 2], discrete, atol=1e-4)
    analytic = z0 - G * t**2 / 2
    err = np.abs(traj.pos[:, 0, 2] - analytic)
    assert np.all(err <= G * H * t / 2 + 1e-4)  # the integrator's O(h) lag, at most 7 mm here
    np.testing.assert_allclose(traj.vel[:, 0, 2], -G * t, atol=1e-4)
    np.testing.assert_allclose(traj.pos[:, 0, :2], 0.0, atol=1e-6)


@pytest.mark.parametrize("e", [0.3, 0.8])
def test_bounce_apex_ratio_is_restitution_squared(e):
    h0 = 10.0
    traj = simulate(spheres([0, 0, h0 + 0.5], material=(e, 0.5, 0.0, 0.0), n_frames=80))
    apexes = flight_apexes(traj, 0.5)
    assert len(apexes) >= 2
    # Tolerance 10 %: contact ERP 0.01 adds a little energy at impact (measured ≤ 4 %).
    assert apexes[0] / h0 == pytest.approx(e**2, rel=0.1)
    assert apexes[1] / apexes[0] == pytest.approx(e**2, rel=0.1)


def test_quaternion_convention_at_the_pybullet_boundary():
    w = 2.0
    q0 = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0])  # 90° about x
    eff = Effects(gravity=False)
    traj = simulate(spheres([0, 0, 5], angvel=[0, 0, w], quat=q0, n_frames=10, effects=eff))
    t = torch.arange(10, dtype=torch.float64)[:, None] * DT
    about_z = torch.cat(
        [torch.cos(w * t / 2), torch.zeros(10, 2, dtype=torch.float64), torch.sin(w * t / 2)], dim=1
    )
    expected = Q.multiply(about_z, torch.as_tensor(q0)[None])  # world-frame ω: exp(ωt) ⊗ q0
    got = torch.as_tensor(traj.quat[:, 0], dtype=torch.float64)
    sign = torch.sign((got * expected).sum(-1, keepdim=True))
    torch.testing.assert_close(got * sign, expected, atol=1e-5, rtol=0)
    _, fd = finite_difference_velocities(
        torch.as_tensor(traj.pos),
        torch.as_tensor(traj.quat),
        torch.as_tensor(traj.vel[0]),
        torch.as_tensor(traj.angvel[0]),
        DT,
    )
    torch.testing.assert_close(fd[:, 0], torch.as_tensor(traj.angvel[:, 0]), atol=1e-3, rtol=0)
    torch.testing.assert_close(
        fd[1:, 0], torch.tensor([[0.0, 0.0, w]]).expand(9, 3), atol=1e-3, rtol=0
    )


def test_finite_difference_velocities_match_engine_velocities_in_flight():
    traj = simulate(spheres([0, 0, 30], vel=[1.5, -2.0, 3.0], angvel=[0.3, -0.2, 1.0], n_frames=12))
    pos, quat = torch.as_tensor(traj.pos), torch.as_tensor(traj.quat)
    vel, ang = torch.as_tensor(traj.vel), torch.as_tensor(traj.angvel)
    fd_v, fd_w = finite_difference_velocities(pos, quat, vel[0], ang[0], DT)
    # Semi-implicit Euler: the mean velocity over a frame is the mean of its end velocities
    # plus g·h/2 (h = physics step).
    expected = 0.5 * (vel[1:] + vel[:-1]) + torch.tensor([0.0, 0.0, -G * H / 2])
    torch.testing.assert_close(fd_v[1:], expected, atol=2e-4, rtol=0)
    torch.testing.assert_close(fd_w[1:], ang[1:], atol=1e-4, rtol=0)


def test_same_scene_gives_identical_arrays():
    scene = spheres(
        [[0, 0, 3], [0.3, 0.2, 5], [-0.4, 0.1, 7]],
        vel=np.random.default_rng(0).normal(size=(3, 3)),
        n_frames=30,
    )
    a, b = simulate(scene), simulate(scene)
    for key in ("pos", "quat", "vel", "angvel"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))


def test_sphere_contact_off_spheres_pass_through_each_other():
    eff = Effects(gravity=False, sphere_contact=False)
    scene = spheres([[-2, 0, 5], [2, 0, 5]], vel=[[2, 0, 0], [-2, 0, 0]], n_frames=21, effects=eff)
    traj = simulate(scene)
    t = np.arange(21)[:, None] * DT
    np.testing.assert_allclose(traj.pos[:, 0, 0], (-2 + 2 * t)[:, 0], atol=1e-5)
    np.testing.assert_allclose(traj.pos[:, 1, 0], (2 - 2 * t)[:, 0], atol=1e-5)
    assert np.linalg.norm(traj.pos[10, 0] - traj.pos[10, 1]) < 1e-5  # coincident at t = 1 s
    # Control: with contact on they bounce back.
    on = simulate(
        spheres(
            [[-2, 0, 5], [2, 0, 5]],
            vel=[[2, 0, 0], [-2, 0, 0]],
            n_frames=21,
            effects=Effects(gravity=False),
        )
    )
    assert on.pos[-1, 0, 0] < -1.0 and on.vel[-1, 0, 0] < 0


def test_rotation_off_keeps_orientation_constant():
    q0 = np.array([0.5, 0.5, 0.5, 0.5])
    eff = Effects(rotation=False)
    scene = spheres(
        [0, 0, 3],
        vel=[3, 0, 0],
        angvel=[0, 0, 5],
        quat=q0,
        material=(0.5, 0.8, 0.01, 0.01),
        n_frames=30,
        effects=eff,
    )
    traj = simulate(scene)
    assert np.all(traj.quat == traj.quat[0])  # bit-identical
    np.testing.assert_allclose(traj.quat[0, 0], q0, atol=1e-6)
    assert np.all(traj.angvel == 0)
    assert traj.pos[-1, 0, 0] > 1.0  # it still moves (slides with friction)
    assert traj.pos[-1, 0, 2] == pytest.approx(0.5, abs=1e-2)


def test_gravity_off_keeps_velocity_constant():
    v0 = np.array([1.0, -0.5, 0.25])
    traj = simulate(spheres([0, 0, 5], vel=v0, n_frames=20, effects=Effects(gravity=False)))
    np.testing.assert_allclose(traj.vel[:, 0], np.tile(v0, (20, 1)), atol=1e-6)
    t = np.arange(20)[:, None] * DT
    np.testing.assert_allclose(traj.pos[:, 0], [0, 0, 5] + v0 * t, atol=1e-5)
    assert traj.attrs["gravity"] == [0.0, 0.0, 0.0]


def test_surface_contact_off_falls_through_the_ground():
    traj = simulate(spheres([0, 0, 2], n_frames=20, effects=Effects(surface_contact=False)))
    t = 1.9
    assert traj.pos[-1, 0, 2] == pytest.approx(2 - G * t**2 / 2, abs=G * H * t / 2 + 1e-3)
    assert traj.pos[-1, 0, 2] < -10


def test_friction_off_keeps_sliding_without_spin():
    eff = Effects(friction=False)
    traj = simulate(
        spheres(
            [0, 0, 0.5], vel=[2, 0, 0], material=(0.5, 0.9, 0.05, 0.05), n_frames=20, effects=eff
        )
    )
    np.testing.assert_allclose(traj.vel[:, 0, 0], 2.0, atol=1e-4)
    np.testing.assert_allclose(traj.angvel[:, 0], 0.0, atol=1e-5)


@pytest.mark.parametrize("height", [230.0, 1000.0])
def test_high_drops_never_pass_through_the_ground(height):
    r = 0.5
    fall = np.sqrt(2 * height / G)
    traj = simulate(
        spheres([0, 0, height], material=(0.3, 0.5, 0.01, 0.01), n_frames=int(fall / DT) + 40)
    )
    assert traj.pos[:, 0, 2].min() > r * 0.5  # never deeper than a quarter diameter
    assert np.all(np.isfinite(traj.pos))
    # It bounced: some frame after landing is moving up, well above the ground.
    landed = int(fall / DT)
    assert traj.vel[landed:, 0, 2].max() > 1.0


def test_unknown_engine_setting_is_one_line():
    with pytest.raises(SceneError, match="unknown engine setting") as e:
        simulate(spheres([0, 0, 1], n_frames=2), {"substep": 3})
    assert "\n" not in str(e.value)
