"""Data out and in: Trajectory.from_arrays, VTK for ParaView, GNS npz and LagrangeBench HDF5,
each written and read back."""

from __future__ import annotations

import dataclasses
import json
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest
import torch
from simdata import trajectory
from torch.testing import assert_close

from physgnn.data import interchange, vtk
from physgnn.physics.scene import Effects, Material, SceneError
from physgnn.physics.trajectory import DEFAULT_DENSITY, Trajectory

T = torch.as_tensor


def mixed(seed: int = 0, n: int = 3, frames: int = 6) -> Trajectory:
    """A hand-made trajectory with two materials."""
    traj = trajectory(n=n, frames=frames, seed=seed)
    materials = np.stack([Material().as_array(), Material(restitution=0.9).as_array()])
    return dataclasses.replace(traj, material=np.arange(n) % 2, materials=materials)


def test_from_arrays_defaults_are_identity_finite_differences_water_and_the_ground():
    pos = np.zeros((3, 2, 3), np.float32)
    pos[:, 0, 2] = [5.0, 4.5, 3.5]
    traj = Trajectory.from_arrays(pos, radius=0.5, dt=0.5)
    assert_close(T(traj.quat[..., 0]), torch.ones(3, 2))
    assert_close(T(traj.vel[:, 0, 2]), T([-1.0, -1.0, -2.0]))  # frame 0 takes frame 1's
    assert_close(T(traj.angvel), torch.zeros(3, 2, 3))
    assert_close(T(traj.mass), torch.full((2,), DEFAULT_DENSITY * 4 / 3 * np.pi / 8))
    assert traj.planes.shape == (1, 11) and traj.plane_kind.tolist() == [0]
    assert traj.material.tolist() == [0, 0] and traj.materials.shape == (1, 4)


def test_from_arrays_keeps_what_it_is_given():
    ref = mixed()
    fields = ("quat", "vel", "angvel", "mass", "material", "materials", "planes", "plane_kind")
    traj = Trajectory.from_arrays(
        ref.pos,
        ref.radius,
        ref.dt,
        quat=ref.quat,
        velocities=(ref.vel, ref.angvel),
        mass=ref.mass,
        materials=(ref.materials, ref.material),
        planes=(ref.planes, ref.plane_kind),
        effects=Effects(rotation=False),
        name=("mine", {"source": "a DEM code"}),
    )
    for key in ("pos", "radius", *fields):
        np.testing.assert_array_equal(getattr(traj, key), getattr(ref, key), err_msg=key)
    assert not traj.effects.rotation
    assert traj.name == "mine" and traj.attrs == {"source": "a DEM code"}


def test_from_arrays_pairs_take_one_value_as_their_first():
    ref = mixed(frames=4)
    table = [[0.5, 0.5, 0.01, 0.01], [0.9, 0.2, 0.01, 0.01]]
    traj = Trajectory.from_arrays(
        ref.pos, ref.radius, ref.dt, velocities=ref.vel, materials=table, name="one"
    )
    np.testing.assert_array_equal(traj.vel, ref.vel)
    finite = Trajectory.from_arrays(ref.pos, ref.radius, ref.dt)
    np.testing.assert_array_equal(traj.angvel, finite.angvel)  # the second: its default
    assert traj.materials.tolist() == np.float32(table).tolist()
    assert traj.material.tolist() == [0] * ref.n_spheres
    assert traj.name == "one" and traj.attrs == {}
    with pytest.raises(SceneError, match=r"planes must be a pair \(rows \[S, 11\], kinds"):
        Trajectory.from_arrays(ref.pos, ref.radius, ref.dt, planes=ref.planes)


def test_from_arrays_finite_differences_match_the_kinematics():
    ref = mixed(frames=5)
    traj = Trajectory.from_arrays(ref.pos, ref.radius, ref.dt, quat=ref.quat)
    finite = ref.with_finite_velocities()
    assert_close(T(traj.vel[1:]), T(finite.vel[1:]).float(), rtol=1e-5, atol=1e-5)
    assert_close(T(traj.angvel[2:]), T(ref.angvel[2:]), rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"pos": np.zeros((4, 3))}, r"pos has shape \[4, 3\], expected \[\*, \*, 3\]"),
        ({"quat": np.zeros((2, 2, 3))}, r"quat has shape \[2, 2, 3\], expected \[2, 2, 4\]"),
        ({"mass": np.ones(3)}, r"mass has shape \[3\], expected \[2\]"),
    ],
)
def test_from_arrays_names_a_wrong_shape(kwargs, message):
    args = {"pos": np.zeros((2, 2, 3)), "radius": 0.5, "dt": 0.1} | kwargs
    with pytest.raises(SceneError, match=message):
        Trajectory.from_arrays(**args)


def test_vtk_round_trip(tmp_path):
    ref = mixed(frames=4)
    series = vtk.write_vtk(ref, tmp_path / "out")
    files = json.loads(series.read_text())["files"]
    assert [f["name"] for f in files] == [f"spheres_{k:05d}.vtu" for k in range(4)]
    assert_close(T([f["time"] for f in files]), T([0.0, 0.1, 0.2, 0.3]), rtol=0, atol=1e-12)
    back = vtk.read_vtk(tmp_path / "out")
    for key in ("pos", "quat", "vel", "angvel", "radius", "mass", "material", "plane_kind"):
        assert_close(T(getattr(back, key)), T(getattr(ref, key)), rtol=0, atol=0, msg=key)
    assert_close(T(back.planes), T(ref.planes), rtol=1e-6, atol=1e-5)
    assert back.dt == pytest.approx(ref.dt)


def test_vtk_files_are_binary_compressed_unstructured_grids(tmp_path):
    ref = mixed(n=3, frames=2)
    vtk.write_vtk(ref, tmp_path / "out")
    root = ET.parse(tmp_path / "out" / "spheres_00001.vtu").getroot()
    assert root.get("type") == "UnstructuredGrid"
    assert root.get("compressor") == "vtkZLibDataCompressor"
    piece = root.find("UnstructuredGrid/Piece")
    assert piece.get("NumberOfPoints") == "3" and piece.get("NumberOfCells") == "3"
    arrays = list(piece.iter("DataArray"))
    assert {a.get("format") for a in arrays} == {"binary"}
    assert {"radius", "velocity", "angular_velocity", "orientation"} <= {
        a.get("Name") for a in arrays
    }
    planes = ET.parse(tmp_path / "out" / "planes.vtu").getroot().find("UnstructuredGrid/Piece")
    assert planes.get("NumberOfPoints") == str(4 * len(ref.planes))
    assert planes.get("NumberOfCells") == str(len(ref.planes))


def test_gns_round_trip_and_metadata(tmp_path):
    splits = {"train": [mixed(0), mixed(1, n=2, frames=5)], "test": [mixed(2)]}
    interchange.write_gns(tmp_path / "out", splits)
    with np.load(tmp_path / "out" / "train.npz", allow_pickle=True) as data:
        pos, types, restitution = data["simulation_trajectory_1"]
    assert pos.shape == (5, 2, 3) and types.tolist() == [5, 6]  # GNS type 3 is kinematic
    assert_close(T(restitution), T([0.5, 0.9]))  # the materials' restitution
    back = interchange.read_gns(tmp_path / "out", "train", radius=0.5)
    for ref, got in zip(splits["train"], back, strict=True):
        np.testing.assert_array_equal(got.pos, ref.pos)
        np.testing.assert_array_equal(got.material, ref.material)
        np.testing.assert_array_equal(got.materials, ref.materials)
    meta = json.loads((tmp_path / "out" / "metadata.json").read_text())
    steps = np.concatenate(
        [
            np.diff(t.pos.astype(np.float64), axis=0).reshape(-1, 3)
            for t in [*splits["train"], *splits["test"]]
        ]
    )
    assert_close(T(meta["vel_mean"], dtype=torch.float64), T(steps.mean(0)))
    assert meta["dt"] == 0.1 and meta["sequence_length"] == 5 and meta["dim"] == 3


def test_lagrangebench_round_trip(tmp_path):
    splits = {"train": [mixed(0)], "val": [mixed(1)], "test": [mixed(2), mixed(3)]}
    out = interchange.write_lagrangebench(tmp_path / "out", splits)
    assert sorted(p.name for p in out.iterdir()) == [
        "metadata.json",
        "physgnn-output.json",
        "test.h5",
        "train.h5",
        "valid.h5",
    ]
    with h5py.File(out / "test.h5") as f:
        assert sorted(f) == ["00000", "00001"] and f["00001/position"].shape == (6, 3, 3)
    back = interchange.read_lagrangebench(out, "test", radius=splits["test"][1].radius)
    for key in ("pos", "radius", "material", "materials"):
        np.testing.assert_array_equal(getattr(back[1], key), getattr(splits["test"][1], key))
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["sequence_length_valid"] == 6 and meta["num_particles_max"] == 3
