"""Exports and imports as faults: nothing of the user's overwritten, an export moved in whole
(a full disk mid-way leaves the previous one), and every bad input or file one line naming it."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from simdata import trajectory
from torch.testing import assert_close

import physgnn.api as pg
from physgnn.data import exports, hdf5_export, interchange, vtk
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


def dead_pid() -> int:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    return dead.pid


def fills_up_at(calls: int, write):
    """``write`` that raises a full disk's OSError at its ``calls``-th call."""
    seen = []

    def writer(*args, **kwargs):
        seen.append(args)
        if len(seen) == calls:
            raise OSError(errno.ENOSPC, "No space left on device", str(args[0]))
        return write(*args, **kwargs)

    return writer


def test_an_export_killed_between_its_renames_is_put_back_by_the_next(tmp_path, monkeypatch):
    old = trajectory(frames=20)
    pg.export(old, tmp_path / "out", "vtk")
    dead = dead_pid()  # killed after moving out aside, before moving its staging in
    aside = tmp_path / f".out.old-{dead}-k1"
    aside.mkdir()
    os.replace(tmp_path / "out", aside / "out")
    (tmp_path / f".out.partial-{dead}-k2").mkdir()
    monkeypatch.setattr(meshio.vtu, "write", fills_up_at(2, meshio.vtu.write))
    with pytest.raises(OSError, match="No space left"):  # the next export fails mid-way too
        pg.export(trajectory(frames=3, seed=1), tmp_path / "out", "vtk")
    assert_close(vtk.read_vtk(tmp_path / "out").pos, old.pos)  # the earlier export, back
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    monkeypatch.undo()
    aside.mkdir()
    os.replace(tmp_path / "out", aside / "out")
    pg.export(trajectory(frames=3, seed=1), tmp_path / "out", "vtk")
    assert vtk.read_vtk(tmp_path / "out").n_frames == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_failed_move_in_puts_the_earlier_export_back(tmp_path, monkeypatch):
    old = trajectory(frames=20)
    pg.export(old, tmp_path / "out", "vtk")
    replace = os.replace

    def fails_for_the_staging_folder(src, dst):
        if Path(src).name.startswith(".out.partial-"):
            raise OSError(errno.EIO, "Input/output error", str(src))
        return replace(src, dst)

    monkeypatch.setattr(exports.os, "replace", fails_for_the_staging_folder)
    with pytest.raises(OSError, match="Input/output error"):
        pg.export(trajectory(frames=3, seed=1), tmp_path / "out", "vtk")
    monkeypatch.undo()
    assert_close(vtk.read_vtk(tmp_path / "out").pos, old.pos)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("fmt", list(WRITES))
def test_an_export_folder_ends_with_the_users_umask(tmp_path, fmt):
    for mask in (0o022, 0o027):
        before = os.umask(mask)
        try:
            pg.export(trajectory(), tmp_path / f"out{mask:o}", fmt)
        finally:
            os.umask(before)
        folder = tmp_path / f"out{mask:o}"
        assert stat.S_IMODE(folder.stat().st_mode) == 0o777 & ~mask  # not mkdtemp's 700
        for path in folder.iterdir():
            assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask, path.name


@pytest.mark.parametrize("fmt", ["gns", "lagrangebench"])
@pytest.mark.parametrize("frames", [1, 2])
def test_an_export_too_short_for_statistics_is_refused_before_any_file(tmp_path, fmt, frames):
    with pytest.raises(ExportError) as err:
        pg.export(trajectory(frames=6).truncated(frames), tmp_path / "out", fmt)
    assert f"hold {frames} frame(s) at most" in one_line(err)
    assert "export at least 3 frames" in str(err.value)
    assert list(tmp_path.iterdir()) == []
    pg.export(trajectory(frames=6).truncated(3), tmp_path / "out", fmt)

    def refuse(name):
        raise AssertionError(f"metadata.json holds {name}: not JSON")

    meta = json.loads((tmp_path / "out" / "metadata.json").read_text(), parse_constant=refuse)
    assert np.isfinite(meta["acc_std"]).all()


# A writer of each format and how a full disk shows in it: an OSError of errno ENOSPC, or
# h5py's OSError without an errno that names the hidden staging file.
H5PY_FULL = (
    "Can't synchronously write data (file write failed: time = Mon Jan  1 00:00:00 2026, "
    "filename = '{}/.out.partial-1-x/test.h5', file descriptor = 5, errno = 28, "
    "error message = 'No space left on device', buf = 0x1, total write size = 4096)"
)


def h5py_fills_up(tmp_path):
    def create_dataset(self, *args, **kwargs):
        raise OSError(H5PY_FULL.format(tmp_path))

    return create_dataset


@pytest.mark.parametrize("fmt", list(WRITES))
def test_a_full_disk_is_one_line_naming_the_folder_and_the_fix(tmp_path, monkeypatch, fmt):
    writer = {
        "vtk": (meshio.vtu, "write", fills_up_at(3, meshio.vtu.write)),
        "gns": (np, "savez_compressed", fills_up_at(1, np.savez_compressed)),
        "lagrangebench": (h5py.Group, "create_dataset", h5py_fills_up(tmp_path)),
        "hdf5": (hdf5_export, "write_split", fills_up_at(1, hdf5_export.write_split)),
    }[fmt]
    monkeypatch.setattr(*writer)
    with pytest.raises(ExportError) as err:
        pg.export(trajectory(), tmp_path / "out", fmt)
    message = one_line(err)
    assert message.startswith(f"export to {fmt}: No space left on device writing {tmp_path}/out")
    assert message.endswith("free space, or export into a folder on another disk")
    assert ".partial" not in message and "[Errno" not in message
    assert isinstance(err.value, OSError) and err.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []  # the staging folder removed


@pytest.mark.parametrize(
    "args, message",
    [
        (
            (None, "out"),
            "trajs must be a Trajectory or a list of them (e.g. [truth, pred]), got NoneType",
        ),
        (
            (trajectory(), None),
            "folder must be a folder's path (str or Path), e.g. 'out', got NoneType",
        ),
        ((trajectory(), 42), "folder must be a folder's path (str or Path), e.g. 'out', got int"),
        (({"train": 3}, "out", "gns"), "trajs['train'] must be a Trajectory or a list of them"),
        (
            ({"test": [trajectory()]}, "out", "vtk"),
            "trajs: splits (a dict) are for gns and lagrangebench, not vtk",
        ),
    ],
)
def test_an_export_of_wrong_arguments_is_one_line_naming_them(tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(pg.ArgumentError) as err:
        pg.export(*args)
    assert message in one_line(err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("folder", ["", ".", "..", "a/..", "/"])
def test_an_export_into_no_folder_of_its_own_is_refused(tmp_path, monkeypatch, folder):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ExportError) as err:
        pg.export(trajectory(), folder, "hdf5")
    assert f"export folder {folder!r} names no folder of its own" in one_line(err)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "names, message",
    [
        (["", "b"], "trajectory 0 is named '', which HDF5 takes as no group's name"),
        (["a", "."], "trajectory 1 is named '.', which HDF5 takes as no group's name"),
        (["a/b", "a_b"], "trajectories 0 and 1 both become the group 'a_b'"),
    ],
)
def test_an_hdf5_export_of_names_hdf5_cannot_take_is_one_line(tmp_path, names, message):
    trajs = [dataclasses.replace(trajectory(seed=i), name=n) for i, n in enumerate(names)]
    with pytest.raises(ExportError) as err:
        pg.export(trajs, tmp_path / "out", "hdf5")
    assert message in one_line(err)
    assert list(tmp_path.iterdir()) == []
