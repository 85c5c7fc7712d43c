"""Dataset report (physgnn.data_report): Table 1 of hand-built splits, report.json, errors."""

import json
import subprocess
import sys

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from physgnn import CONF_DIR
from physgnn.data.dataset import DatasetError, write_split
from physgnn.evaluation.data_report import KEYS, DataReportError, data_report
from physgnn.physics.scene import Effects, ground_plane
from physgnn.physics.trajectory import Trajectory

CONF = CONF_DIR
G = 9.81


def traj(pos, name):
    """Spheres of radius 0.5 and mass 1 at ``pos [T, N, 3]``, at rest at frame 0."""
    pos = np.asarray(pos, np.float32)
    t, n = pos.shape[:2]
    quat = np.zeros((t, n, 4), np.float32)
    quat[..., 0] = 1
    return Trajectory(
        name=name,
        pos=pos,
        quat=quat,
        vel=np.zeros((t, n, 3), np.float32),
        angvel=np.zeros((t, n, 3), np.float32),
        radius=np.full(n, 0.5, np.float32),
        mass=np.ones(n, np.float32),
        material=np.zeros(n, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=np.zeros((1, 4), np.float32),
        dt=0.1,
        effects=Effects(),
    )


# A: two resting spheres on the ground overlapping by 0.2 (normalised 0.2), no energy change
# (E_0 = 0: divided by Σ m·g·r, gain 0). B: one sphere sunk 0.1 into the ground, another
# jumping up 0.5 m at the last frame with engine velocity 0: gain g·0.5 / E_0,
# E_0 = g·2.5 − g·0.1; with the finite-difference velocity 5 m/s, (0.5·25 + g·0.5) / E_0.
A = traj([[[0, 0, 0.5], [0.8, 0, 0.5]]] * 3, "a")
B = traj([[[5, 0, 0.4], [9, 0, 3]], [[5, 0, 0.4], [9, 0, 3]], [[5, 0, 0.4], [9, 0, 3.5]]], "b")
GAIN_B = (G * 0.5) / (G * 2.4)
GAIN_B_FINITE = (12.5 + G * 0.5) / (G * 2.4)


@pytest.fixture
def dataset(tmp_path):
    write_split(tmp_path / "test.h5", [A, B], {"split": "test", "preset": "hand"})
    write_split(tmp_path / "ood.h5", [A], {"split": "ood", "preset": "hand"})
    return tmp_path


def cfg_for(folder, *overrides):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose("data_report", overrides=[f"dataset={folder}", *overrides])


def test_table1_means_and_stds_and_report_json(dataset, capsys):
    summary = data_report(cfg_for(dataset))
    written = json.loads((dataset / "report.json").read_text())
    assert written == summary
    assert list(written) == ["test", "ood"] and all(list(written[s]) == list(KEYS) for s in written)
    assert all(set(v) == {"mean", "std"} for s in written.values() for v in s.values())
    test, ood = written["test"], written["ood"]
    assert test["energy_gain"]["mean"] == pytest.approx(GAIN_B / 2, rel=1e-5)
    assert test["energy_gain"]["std"] == pytest.approx(GAIN_B / 2, rel=1e-5)
    assert test["depth_sphere"] == pytest.approx({"mean": 0.1, "std": 0.1}, rel=1e-5)
    assert test["pct_sphere"] == pytest.approx({"mean": 50.0, "std": 50.0})
    assert test["depth_ground"] == pytest.approx({"mean": 0.05, "std": 0.05}, rel=1e-4)
    assert test["pct_ground"] == pytest.approx({"mean": 25.0, "std": 25.0})
    assert test["pct_static"] == {"mean": 0.0, "std": 0.0}
    assert ood["depth_sphere"] == pytest.approx({"mean": 0.2, "std": 0.0}, rel=1e-5, abs=1e-12)
    assert ood["energy_gain"] == {"mean": 0.0, "std": 0.0}
    out = capsys.readouterr().out
    assert "ours test" in out and "4.22e-03 ± 2.17e-03" in out and "report.json" in out
    assert f"test {GAIN_B_FINITE / 2:.3g} ± {GAIN_B_FINITE / 2:.3g}" in out


def test_tolerance_is_a_fraction_of_the_diameter(dataset):
    summary = data_report(cfg_for(dataset, "tol=0.15"))
    assert summary["test"]["pct_ground"]["mean"] == 0.0  # 0.1 is below the tolerance
    assert summary["test"]["pct_sphere"]["mean"] == 50.0  # 0.2 is above it
    assert summary["test"]["depth_ground"]["mean"] == pytest.approx(0.05, rel=1e-4)


def test_missing_split_or_folder_is_one_clear_error(dataset, tmp_path):
    (dataset / "ood.h5").unlink()
    with pytest.raises(DatasetError, match="ood.h5 not found"):
        data_report(cfg_for(dataset))
    with pytest.raises(DataReportError, match="not found"):
        data_report(cfg_for(tmp_path / "nope"))
    write_split(dataset / "ood.h5", [], {"split": "ood", "preset": "hand"})
    with pytest.raises(DataReportError, match="ood.h5: split has no trajectory"):
        data_report(cfg_for(dataset))


def test_cli_missing_dataset_prints_one_line_and_exits_2(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "physgnn.data_report", f"dataset={tmp_path / 'missing'}"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and proc.stderr.startswith("error: dataset folder")
    assert list(tmp_path.iterdir()) == []  # nothing written, not even Hydra's folders


def test_cli_truncated_file_is_one_error_line(dataset, capsys):
    from physgnn.data_report import main

    data = (dataset / "test.h5").read_bytes()
    (dataset / "test.h5").write_bytes(data[: len(data) // 2])
    with pytest.raises(SystemExit) as exit_info:
        main.__wrapped__(cfg_for(dataset))  # the body of the Hydra entry point
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "truncated or corrupt" in err and "\n" not in err
