"""The invariance checks of make eval (physgnn/evaluation/invariance.py), their report section
and the targets table (physgnn/report/targets.py), on analytic scenes and an untrained model."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from simdata import learned

from physgnn.evaluation import invariance as inv
from physgnn.physics.energy import G
from physgnn.report import invariance as section


def test_the_flying_block_is_exact_ballistic_flight():
    block = inv.flying_block(frames=5)
    assert block.pos.shape == (5, 24, 3)
    dz = np.diff(block.vel[..., 2], axis=0)
    np.testing.assert_allclose(dz, -G * block.dt, rtol=1e-12)
    np.testing.assert_allclose(block.vel[0], np.tile([2.0, -1.0, 3.0], (24, 1)))
    change, dvz = inv.block_errors(block, block)  # the truth as its own rollout: no error
    assert change == pytest.approx(0.0, abs=1e-9) and dvz == pytest.approx(0.0, abs=1e-9)


def test_the_collision_is_one_to_eight_and_starts_apart():
    hit = inv.collision()
    assert hit.mass[1] / hit.mass[0] == pytest.approx(8.0)
    gap = np.linalg.norm(hit.pos[2, 1] - hit.pos[2, 0]) - hit.radius.sum()
    assert gap > 0  # the seed frames (H = 2) are before the impact
    assert hit.materials[0, 1:].tolist() == [0.0, 0.0, 0.0]  # frictionless


def test_the_ground_collision_slides_on_the_ground_and_starts_apart():
    hit = inv.ground_collision()
    assert hit.mass[1] / hit.mass[0] == pytest.approx(8.0)
    np.testing.assert_allclose(hit.pos[:, :, 2], np.tile(hit.radius, (hit.n_frames, 1)))
    gap = np.linalg.norm(hit.pos[2, 1] - hit.pos[2, 0]) - hit.radius.sum()
    assert gap > 0  # the seed frames are before the impact
    assert hit.materials[0, 1:].tolist() == [0.0, 0.0, 0.0]  # frictionless
    np.testing.assert_allclose(hit.vel[:, :, 0] @ hit.mass, hit.vel[0, :, 0] @ hit.mass)


def test_resting_grids_touch_and_weigh_what_they_say():
    heavy, light = inv.resting_grid(None, 6), inv.resting_grid(1.0, 6)
    assert np.all(light.mass == 1.0) and heavy.mass[0] == pytest.approx(inv.sphere_mass(0.75))
    assert np.all(heavy.pos == heavy.pos[0]) and np.all(heavy.vel == 0)
    dist = np.linalg.norm(heavy.pos[0, 0] - heavy.pos[0, 1])
    assert dist == pytest.approx(2 * 0.75)  # touching neighbours


def test_an_untrained_default_keeps_the_block_and_every_row_is_there():
    torch.manual_seed(0)
    sim = learned(H=2, M=1, hidden=8).eval()
    rows = inv.invariance_rows("untrained", sim, rest_frames=4)
    kinds = [r["kind"] for r in rows]
    assert kinds.count("flying_block") == 1 and kinds.count("collision") == 1
    assert kinds.count("resting_grid") == 2 and kinds.count("sliding_row") == 1
    assert kinds.count("ground_collision") == 1
    assert kinds.count("bounce") == len(inv.BOUNCE_MATERIALS) * len(inv.BOUNCE_MASSES)
    block = rows[0]
    # no pp edge between spheres moving as one, no plane in reach: the gravity prior, exact to
    # float32 rounding of positions up to 30 m apart
    assert block["passed"] and block["value"] < 1e-3 and block["value2"] < 5e-4
    text = section.section(rows)
    passed = sum(r["passed"] for r in rows)
    assert f"`untrained` {passed}/{len(rows)}" in text and "flying_block" in text


def test_the_section_says_when_there_are_no_checks():
    assert "No invariance checks" in section.section([])


def test_the_targets_table_reads_an_eval_folder(tmp_path):
    from physgnn.files import write_rows
    from physgnn.report import stability, targets

    metrics = [
        {"run": "r", "split": "test", "mse": m, "chamfer": 2 * m, "diverged_at": None}
        for m in (1.0, 3.0)
    ]
    write_rows(tmp_path / "metrics.csv", metrics, ["run", "split", "mse", "chamfer", "diverged_at"])
    stab = [
        {
            "run": "r",
            "source": "ood",
            "scene": "ood_cubes",
            "max_pen_sphere": 0.5,
            "tunnelled": 2,
            "rest_drift": None,
        },
        {
            "run": "r",
            "source": "hard",
            "scene": "resting_pile",
            "max_pen_sphere": 0.01,
            "tunnelled": 0,
            "rest_drift": 0.25,
        },
        {
            "run": "ground_truth",
            "source": "ood",
            "scene": "ood_cubes",
            "max_pen_sphere": 0.0,
            "tunnelled": 0,
            "rest_drift": None,
        },
    ]
    stability.write_csv(tmp_path / "stability.csv", stab)
    checks = [
        {
            "run": "r",
            "kind": "flying_block",
            "setting": "",
            "value": 1e-4,
            "value2": 0.0,
            "limit": 0.1,
            "passed": True,
            "diverged_at": None,
        }
    ]
    section.write_csv(tmp_path / "invariance.csv", checks)
    (row,) = targets.target_rows(tmp_path)  # the ground truth is no run
    assert row[:8] == ["`r`", "2", "4", "0/4", "0.5", "2", "0.25", "– / –"]
    assert row[8] == "1/1 (1.00e-04)" and row[9] == "–"
    assert len(row) == len(targets.HEADER)
