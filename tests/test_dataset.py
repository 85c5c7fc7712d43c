"""HDF5 schema, atomic writes, checked reads (physgnn.data.dataset) and statistics
(physgnn.data.stats)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from handmade import linear_traj

from physgnn import __version__
from physgnn.data.dataset import CHUNK_FRAMES, SCHEMA_VERSION, DatasetError, read_split, write_split
from physgnn.data.stats import compute_stats, read_stats, write_stats


def test_round_trip_schema_and_attributes(tmp_path):
    path = tmp_path / "tiny" / "test.h5"
    a, b = linear_traj(name="a"), linear_traj(t=7, n=3, name="b")
    write_split(path, [a, b], {"split": "test", "preset": "tiny"})
    with h5py.File(path) as f:
        assert f.attrs["schema_version"] == SCHEMA_VERSION
        assert f.attrs["split"] == "test" and f.attrs["preset"] == "tiny"
        assert sorted(f) == ["traj_00000", "traj_00001"]
        g = f["traj_00001"]
        assert g["pos"].shape == (7, 3, 3) and g["quat"].shape == (7, 3, 4)
        assert g["pos"].chunks[0] == min(7, CHUNK_FRAMES) and g["pos"].compression == "gzip"
        assert g["material"].dtype == np.int64 and g["planes"].shape == (1, 11)
        assert json.loads(g.attrs["effects"])["rotation"] is False
        assert g.attrs["seed"] == 7 and g.attrs["substeps"] == 20
        assert g.attrs["physgnn_version"] == __version__
        assert g.attrs["scene"] == "lin_scene" and g.attrs["engine"] == "pybullet test"
        np.testing.assert_array_equal(g.attrs["gravity"], [0, 0, -9.81])
    back = read_split(path)
    assert [t.attrs["group"] for t in back] == ["traj_00000", "traj_00001"]
    for orig, got in zip([a, b], back, strict=True):
        for key in ("pos", "quat", "vel", "angvel", "radius", "mass", "material", "planes"):
            np.testing.assert_array_equal(getattr(got, key), getattr(orig, key))
        assert got.dt == orig.dt and got.effects == orig.effects
        assert got.attrs["scene_config"] == "name: lin_scene\n"
    assert not (tmp_path / "tiny" / "test.h5.tmp").exists()


def test_failed_write_keeps_the_previous_file(tmp_path):
    path = tmp_path / "d" / "train.h5"
    write_split(path, [linear_traj()], {"split": "train", "preset": "d"})
    before = path.read_bytes()
    bad = linear_traj()
    bad.attrs["seed"] = "not an int"
    with pytest.raises(ValueError):
        write_split(path, [linear_traj(), bad], {"split": "train", "preset": "d"})
    assert path.read_bytes() == before
    assert not (tmp_path / "d" / "train.h5.tmp").exists()


def one_line_error(path, match):
    with pytest.raises(DatasetError, match=match) as e:
        read_split(path)
    assert "\n" not in str(e.value)


def test_missing_file_names_the_command(tmp_path, monkeypatch):
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path))  # where make data writes
    path = tmp_path / "data" / "small" / "train.h5"
    one_line_error(path, r"not found: run `make data PRESET=small`")


def test_truncated_file(tmp_path):
    path = tmp_path / "d" / "train.h5"
    write_split(path, [linear_traj(t=200)], {"split": "train", "preset": "d"})
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    one_line_error(path, "truncated or corrupt")


def test_other_schema_version(tmp_path):
    path = tmp_path / "d" / "train.h5"
    write_split(path, [linear_traj()], {"split": "train", "preset": "d"})
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = SCHEMA_VERSION + 1
    one_line_error(path, f"schema version {SCHEMA_VERSION + 1}, this physgnn reads")


def test_missing_field(tmp_path):
    path = tmp_path / "d" / "train.h5"
    write_split(path, [linear_traj()], {"split": "train", "preset": "d"})
    with h5py.File(path, "a") as f:
        del f["traj_00000/quat"]
    one_line_error(path, r"missing field\(s\) \['quat'\]")


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_nan_in_a_trajectory(tmp_path, value):
    traj = linear_traj()
    traj.pos[3, 1, 2] = value
    path = tmp_path / "d" / "train.h5"
    write_split(path, [traj], {"split": "train", "preset": "d"})
    one_line_error(path, "traj_00000: pos contains NaN or inf")


def test_stats_of_constant_velocity_trajectories(tmp_path):
    v = np.array([1.0, -2.0, 0.5])
    # dt = 1/8: positions and their differences are exact in float32.
    trajs = [linear_traj(t=5, n=2, v=v, dt=0.125), linear_traj(t=4, n=2, v=v, dt=0.125)]
    stats = compute_stats(trajs)
    np.testing.assert_allclose(stats["vel"]["mean"], v, atol=1e-5)
    assert stats["vel"]["std"] == [1e-6] * 3  # floored, never 0
    assert min(stats["delta_vel"]["std"]) >= 1e-6 and min(stats["angvel"]["std"]) >= 1e-6
    np.testing.assert_allclose(stats["delta_vel"]["mean"], 0.0, atol=1e-5)
    assert stats["radius"] == {"mean": 0.5, "std": 1e-6}
    assert stats["mass"]["mean"] == pytest.approx(2.0) and stats["mass"]["std"] == pytest.approx(
        1.0
    )
    assert stats["max_speed"] == pytest.approx(np.linalg.norm(v), rel=1e-5)
    assert stats["n_pairs"] == 4 + 3
    write_stats(tmp_path, stats)
    assert read_stats(tmp_path) == json.loads(json.dumps(stats))


def test_read_stats_errors(tmp_path):
    with pytest.raises(DatasetError, match="stats.json not found"):
        read_stats(tmp_path)
    (tmp_path / "stats.json").write_text('{"vel": {}}')
    with pytest.raises(DatasetError, match="missing key"):
        read_stats(tmp_path)
