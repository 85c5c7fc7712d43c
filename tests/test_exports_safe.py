"""Exports and imports as faults: nothing of the user's overwritten, an export moved in whole
(a full disk mid-way leaves the previous one), and every bad input or file one line naming it."""

from __future__ import annotations

import dataclasses
import errno
import json
import subprocess
import sys
import zipfile

import meshio
import numpy as np
import pytest
from simdata import trajectory
from torch.testing import assert_close

import physgnn.api as pg
from physgnn.data import interchange, vtk
from physgnn.data.dataset import DatasetError
from physgnn.data.exports import ExportError
from physgnn.physics.scene import SceneError

# The file of each format that a user's file of the same name stands for.
WRITES = {
    "vtk": "spheres_00000.vtu",
    "gns": "metadata.json",
    "lagrangebench": "test.h5",
    "hdf5": "trajectories.h5",
}


def one_line(err) -> str:
    assert "\n" not in str(err.value)
    return str(err.value)


@pytest.mark.parametrize("fmt", list(WRITES))
def test_an_export_never_writes_over_a_file_of_yours(tmp_path, fmt):
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / WRITES[fmt]).write_text("mine")
    with pytest.raises(FileExistsError) as err:
        pg.export(trajectory(), folder, fmt)
    assert f"holds {WRITES[fmt]}, which no export wrote there" in one_line(err)
    assert [p.name for p in folder.iterdir()] == [WRITES[fmt]]
    assert (folder / WRITES[fmt]).read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging left


@pytest.mark.parametrize("fmt", list(WRITES))
def test_an_export_replaces_an_earlier_export_whole(tmp_path, fmt):
    pg.export(trajectory(frames=20), tmp_path / "out", fmt)
    (tmp_path / "out" / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="holds notes.txt"):
        pg.export(trajectory(frames=3), tmp_path / "out", fmt)
    (tmp_path / "out" / "notes.txt").unlink()
    pg.export(trajectory(frames=3), tmp_path / "out", fmt)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_shorter_vtk_export_leaves_no_stale_frame(tmp_path):
    pg.export(trajectory(frames=20), tmp_path / "out", "vtk")
    pg.export(trajectory(frames=3, seed=1), tmp_path / "out", "vtk")
    assert sorted(p.name for p in (tmp_path / "out").glob("spheres_*.vtu")) == [
        "spheres_00000.vtu",
        "spheres_00001.vtu",
        "spheres_00002.vtu",
    ]
    assert_close(vtk.read_vtk(tmp_path / "out").pos, trajectory(frames=3, seed=1).pos)


def test_a_full_disk_mid_export_leaves_the_previous_export_whole(tmp_path, monkeypatch):
    old = trajectory(frames=20)
    pg.export(old, tmp_path / "out", "vtk")
    write, calls = meshio.vtu.write, []

    def fills_up(path, *args, **kwargs):
        calls.append(path)
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return write(path, *args, **kwargs)

    monkeypatch.setattr(meshio.vtu, "write", fills_up)
    with pytest.raises(OSError, match="No space left"):
        pg.export(trajectory(frames=3, seed=1), tmp_path / "out", "vtk")
    back = vtk.read_vtk(tmp_path / "out")
    assert back.n_frames == 20
    assert_close(back.pos, old.pos)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("fmt", list(WRITES))
def test_an_export_of_a_diverged_trajectory_is_refused_before_any_file(tmp_path, fmt):
    traj = trajectory(frames=6)
    traj.pos[4, 1, 2] = np.nan
    with pytest.raises(ExportError) as err:
        pg.export(traj, tmp_path / "out", fmt)
    assert "holds nan in pos at frame 4" in one_line(err)
    assert "traj.truncated(4)" in str(err.value) and not (tmp_path / "out").exists()


def test_an_export_of_nothing_or_of_one_name_twice_is_refused_in_one_line(tmp_path):
    with pytest.raises(ExportError, match="of no trajectory") as err:
        pg.export([], tmp_path / "out", "hdf5")
    one_line(err)
    twin = dataclasses.replace(trajectory(seed=1), name=trajectory().name)
    with pytest.raises(ExportError, match="trajectories 0 and 1 are both named 'hand_0'") as err:
        pg.export([trajectory(), twin], tmp_path / "out", "gns")
    one_line(err)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("fmt", ["vtk", "gns", "lagrangebench"])
def test_load_trajectories_of_an_export_names_its_reader(tmp_path, fmt):
    pg.export(trajectory(), tmp_path / "out", fmt)
    for path in (tmp_path / "out", next((tmp_path / "out").iterdir())):
        with pytest.raises(
            DatasetError,
            match=f"is a {fmt} export, not a physgnn HDF5 file: read it with physgnn.data.",
        ) as err:
            pg.load_trajectories(path)
        assert "generate" not in one_line(err)


def test_load_trajectories_of_an_hdf5_export_loads_it(tmp_path):
    path = pg.export([trajectory(), trajectory(seed=1)], tmp_path / "out", "hdf5")
    assert [t.name for t in pg.load_trajectories(path)] == ["hand_0", "hand_1"]
    with pytest.raises(DatasetError, match="trajectories.h5") as err:
        pg.load_trajectories(tmp_path / "out")
    one_line(err)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"dt": 0.0}, r"dt must be a number > 0 \(seconds between frames\), got 0.0"),
        ({"dt": -0.1}, r"dt must be a number > 0 \(seconds between frames\), got -0.1"),
        ({"dt": float("nan")}, r"dt must be a number > 0 \(seconds between frames\), got nan"),
        ({"radius": [0.5, -1.0]}, r"radius must be a number > 0 \(metres\), got -1 \(sphere 1\)"),
        ({"radius": [0.5, 0.5, 0.5]}, r"radius has shape \[3\], expected \[2\]"),
        ({"pos": np.full((2, 2, 3), np.nan)}, "pos holds nan at frame 0, sphere 0"),
    ],
)
def test_trajectory_from_arrays_refuses_what_no_trajectory_is(kwargs, message):
    args = {"pos": np.ones((2, 2, 3)), "radius": 0.5, "dt": 0.1} | kwargs
    with pytest.raises(SceneError, match=message) as err:
        pg.trajectory_from_arrays(**args)
    one_line(err)


@pytest.mark.parametrize("fmt", ["gns", "lagrangebench"])
def test_a_reader_refuses_a_bad_dt_or_radius_naming_the_file(tmp_path, fmt):
    read = {"gns": interchange.read_gns, "lagrangebench": interchange.read_lagrangebench}[fmt]
    pg.export(trajectory(), tmp_path / "out", fmt)
    with pytest.raises(DatasetError, match="radius must be a number > 0") as err:
        read(tmp_path / "out", "test", radius=-1.0)
    assert str(tmp_path / "out" / "test.") in one_line(err)
    meta = json.loads((tmp_path / "out" / "metadata.json").read_text())
    (tmp_path / "out" / "metadata.json").write_text(json.dumps(meta | {"dt": -0.1}))
    with pytest.raises(DatasetError, match="dt must be a number > 0") as err:
        read(tmp_path / "out", "test", radius=0.5)
    del meta["dt"]
    (tmp_path / "out" / "metadata.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="metadata.json is missing, truncated or not") as err:
        read(tmp_path / "out", "test", radius=0.5)
    assert "KeyError" in one_line(err)


@pytest.mark.parametrize(
    "fmt, name", [("gns", "test.npz"), ("lagrangebench", "test.h5"), ("vtk", "spheres_00001.vtu")]
)
def test_a_truncated_or_foreign_import_file_is_named_in_one_line(tmp_path, fmt, name):
    readers = {"gns": interchange.read_gns, "lagrangebench": interchange.read_lagrangebench}
    read = vtk.read_vtk if fmt == "vtk" else lambda folder: readers[fmt](folder, "test", 0.5)
    pg.export(trajectory(), tmp_path / "out", fmt)
    path = tmp_path / "out" / name
    path.write_bytes(path.read_bytes()[:200])  # truncated
    with pytest.raises(DatasetError, match=f"{path} is ") as err:
        read(tmp_path / "out")
    one_line(err)
    path.write_text("<VTKFile><PolyData></VTKFile>" if fmt == "vtk" else "not this format")
    with pytest.raises(DatasetError, match=f"{path} is ") as err:
        read(tmp_path / "out")
    one_line(err)


def test_a_foreign_npz_names_the_file(tmp_path):
    (tmp_path / "metadata.json").write_text(json.dumps({"dt": 0.1}))
    with zipfile.ZipFile(tmp_path / "test.npz", "w") as z:
        z.writestr("other.npy", b"not an array")
    with pytest.raises(DatasetError, match="test.npz is missing, truncated or not a gns") as err:
        interchange.read_gns(tmp_path, "test", 0.5)
    one_line(err)


def test_the_leftovers_of_a_killed_export_go_at_the_next_one(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    leftovers = [tmp_path / f".out.partial-{dead.pid}-x1", tmp_path / f".out.old-{dead.pid}-x2"]
    for path in leftovers:
        path.mkdir()
        (path / "spheres_00000.vtu").write_text("half")
    (tmp_path / ".out.partial-notes").mkdir()  # not named as an export's: kept
    pg.export(trajectory(), tmp_path / "out", "vtk")
    assert sorted(p.name for p in tmp_path.iterdir()) == [".out.partial-notes", "out"]
