"""The pybullet ground truth against analytic answers, on every event (physgnn.oracles)."""

from __future__ import annotations

import numpy as np
import pytest

from physgnn.groundtruth import oracles as O
from physgnn.groundtruth.settings import EngineSettings

G = 9.81


@pytest.mark.parametrize("offset", [0.0, 3e-4])
@pytest.mark.parametrize("e", [0.7, 0.8, 0.9])
def test_eight_bounces_keep_restitution_squared(e, offset):
    # offset 0.3 mm: a physics step ends just above the ground before the first impact; a
    # 1 mm contact-breaking threshold started that contact early (bounces up to 14 % short).
    ratios = O.bounce_ratios(e, height=20.0, offset=offset)
    assert len(ratios) >= 8
    np.testing.assert_allclose(ratios[:8], 1.0, atol=0.04)


@pytest.mark.parametrize("e", [0.3, 0.5])
def test_low_restitution_bounces_keep_restitution_squared_while_fast(e):
    # Slower impacts than the restitution velocity threshold (0.5 m/s) are inelastic by design;
    # every bounce whose impact is faster than 1 m/s keeps e² within 4 %.
    ratios = O.bounce_ratios(e, height=20.0)
    fast = O.impact_speeds(e, 20.0, len(ratios)) > 1.0
    assert fast.sum() >= 3
    np.testing.assert_allclose(ratios[fast], 1.0, atol=0.04)


@pytest.mark.parametrize("substeps", [10, 20, 40])
def test_free_fall_error_is_the_integrators_lag(substeps):
    # Semi-implicit Euler lags ½gt² by g·h·t/2 (h = dt / substeps): 9.8 cm after 4 s at 5 ms.
    h, t = 0.1 / substeps, 4.0
    assert O.free_fall_error(substeps, seconds=t) == pytest.approx(G * h * t / 2, rel=1e-3)


def test_default_free_fall_error_after_four_seconds_is_under_5_cm():
    assert O.free_fall_error(EngineSettings().substeps) < 0.05


def test_head_on_frictionless_impact_conserves_momentum():
    masses, speeds, e = (1.0, 3.0), (4.0, -2.0), 0.7
    err, after = O.head_on_momentum_error(e, masses, speeds)
    assert err < 0.01
    # Bullet combines restitution by product: the pair collides with e².
    np.testing.assert_allclose(after, O.head_on_analytic(e * e, masses, speeds), atol=0.05)


@pytest.mark.parametrize(
    ("slope", "friction", "slides"),
    [(30.0, 0.5, True), (25.0, 0.5, False), (30.0, 0.6, False), (45.0, 0.8, True)],
)
def test_sphere_on_a_ramp_slides_only_beyond_the_friction_angle(slope, friction, slides):
    assert (np.tan(np.deg2rad(slope)) > friction) == slides
    travel = O.ramp_travel(slope, friction, seconds=1.0)
    if slides:
        assert travel == pytest.approx(O.ramp_analytic(slope, friction), rel=0.05)
    else:
        assert abs(travel) < 1e-3
