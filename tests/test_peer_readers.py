"""The exports as the peers' own readers take them: GNS, LagrangeBench, meshio and pyvista.

The GNS and LagrangeBench readers are minimal re-implementations of the peers' code (each cites
the file it follows); meshio is a dependency; pyvista is used when installed."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
import torch
from simdata import trajectory
from torch.testing import assert_close

from physgnn.data import interchange, vtk
from physgnn.data.exports import ExportError
from physgnn.physics.scene import Material
from physgnn.physics.trajectory import DEFAULT_DENSITY

T = torch.as_tensor

# geoelements/gns gns/train.py (and deepmind-research learning_to_simulate/train.py)
GNS_NUM_PARTICLE_TYPES = 9
GNS_KINEMATIC_PARTICLE_ID = 3
# tumaer/lagrangebench lagrangebench/utils.py: NodeType and get_kinematic_mask
LB_KINEMATIC_TYPES = (1, 2, -1)  # SOLID_WALL, MOVING_WALL, PAD_VALUE


def materials_scene(n_materials: int, seed: int = 0):
    """A trajectory of ``n_materials`` spheres, one per material (restitution 0.1, 0.2, ...)."""
    traj = trajectory(n=n_materials, frames=8, seed=seed)
    table = np.stack([Material(restitution=0.1 * (k + 1)).as_array() for k in range(n_materials)])
    return dataclasses.replace(traj, material=np.arange(n_materials), materials=table)


def gns_samples(path: Path, input_length_sequence: int = 6):
    """GNS's training samples as geoelements/gns gns/data_loader.py builds them
    (load_npz_data, then SamplesDataset.__getitem__ for every index)."""
    with np.load(path, allow_pickle=True) as data_file:
        data = [item for _, item in data_file.items()]
    assert len(data[0]) >= 3  # _material_property_as_feature
    samples = []
    for x, particle_type, material_property in data:
        for time_idx in range(input_length_sequence, x.shape[0]):
            positions = np.transpose(x[time_idx - input_length_sequence : time_idx], (1, 0, 2))
            types = np.full(positions.shape[0], particle_type, dtype=int)
            props = np.full(positions.shape[0], material_property, dtype=float)
            samples.append((positions, types, props, x[time_idx]))
    return samples


def test_gns_reads_moving_types_in_its_embedding_and_the_material_property(tmp_path):
    scene = materials_scene(8)
    interchange.write_gns(tmp_path / "gns", {"test": [scene]})
    samples = gns_samples(tmp_path / "gns" / "test.npz")
    assert len(samples) == scene.n_frames - 6
    positions, types, props, label = samples[0]
    assert positions.shape == (8, 6, 3) and label.shape == (8, 3)
    assert set(types.tolist()) <= set(range(GNS_NUM_PARTICLE_TYPES)) - {GNS_KINEMATIC_PARTICLE_ID}
    assert len(set(types.tolist())) == 8  # one type per material
    assert_close(T(props), T(scene.materials[:, 0], dtype=torch.float64))  # restitution
    back = interchange.read_gns(tmp_path / "gns", "test", radius=scene.radius)
    np.testing.assert_array_equal(back[0].material, scene.material)


def test_gns_export_of_more_materials_than_its_types_is_refused_in_one_line(tmp_path):
    with pytest.raises(ExportError, match="GNS embeds 8 moving particle types") as err:
        interchange.write_gns(tmp_path / "gns", {"test": [materials_scene(9)]})
    assert "\n" not in str(err.value) and not (tmp_path / "gns").exists()


def lb_dataset(folder: Path, split: str, input_seq_length: int = 6):
    """LagrangeBench's windows, as tumaer/lagrangebench lagrangebench/data/data.py H5Dataset
    reads them (get_window for every index): the first trajectory's length for all."""
    with h5py.File(folder / f"{split}.h5", "r") as f:
        keys = list(f.keys())
        sequence_length = f["00000/position"].shape[0]
        windows = []
        for key in keys:
            for el in range(sequence_length - input_seq_length - 1):
                pos = f[key]["position"][el : el + input_seq_length + 1].transpose((1, 0, 2))
                windows.append((pos, f[key]["particle_type"][:]))
    return windows


def lb_e_kin(rollout: np.ndarray, metadata: dict) -> np.ndarray:
    """LagrangeBench's e_kin of a rollout ``[T, N, 3]`` per frame pair (stride 1), as
    tumaer/lagrangebench lagrangebench/evaluate/metrics.py computes it."""
    dt = metadata["dt"] * metadata["write_every"]
    velocity = (rollout[1:] - rollout[:-1]) / dt
    return (velocity**2).sum(axis=(1, 2)) * metadata["dx"] ** metadata["dim"]


def test_lagrangebench_reads_spheres_as_moving_particles_and_a_kinetic_energy(tmp_path):
    scene = materials_scene(4)
    scene = dataclasses.replace(scene, radius=np.full(4, 0.5, np.float32))
    interchange.write_lagrangebench(tmp_path / "lb", {"test": [scene]})
    windows = lb_dataset(tmp_path / "lb", "test")
    assert len(windows) == scene.n_frames - 7
    for pos, types in windows:
        assert pos.shape == (4, 7, 3) and not np.isin(types, LB_KINEMATIC_TYPES).any()
    with h5py.File(tmp_path / "lb" / "test.h5") as f:
        np.testing.assert_array_equal(f["00000/material"][:], scene.material)  # kept aside
    meta = json.loads((tmp_path / "lb" / "metadata.json").read_text())
    e_kin = lb_e_kin(scene.pos.astype(np.float64), meta)
    # dx**3 is a sphere's volume: e_kin * density / 2 is the kinetic energy of the spheres
    mass = DEFAULT_DENSITY * 4 / 3 * np.pi * 0.5**3
    velocity = np.diff(scene.pos.astype(np.float64), axis=0) / scene.dt
    assert_close(T(e_kin * DEFAULT_DENSITY / 2), T(0.5 * mass * (velocity**2).sum(axis=(1, 2))))


def test_lagrangebench_split_of_two_lengths_is_refused_in_one_line(tmp_path):
    short = dataclasses.replace(materials_scene(2, seed=1), name="short").truncated(5)
    with pytest.raises(ExportError, match="one length per split") as err:
        interchange.write_lagrangebench(tmp_path / "lb", {"test": [materials_scene(2), short]})
    assert "\n" not in str(err.value) and not (tmp_path / "lb").exists()


def test_vtk_files_read_in_meshio(tmp_path):
    scene = materials_scene(3)
    vtk.write_vtk(scene, tmp_path / "vtk")
    mesh = meshio.read(tmp_path / "vtk" / "spheres_00004.vtu")
    assert_close(T(mesh.points), T(scene.pos[4]), rtol=0, atol=0)
    assert_close(T(mesh.point_data["orientation"]), T(scene.quat[4]), rtol=0, atol=0)
    assert mesh.cells[0].type == "vertex" and len(mesh.cells[0].data) == 3
    planes = meshio.read(tmp_path / "vtk" / "planes.vtu")
    assert planes.cells[0].type == "quad" and len(planes.cells[0].data) == len(scene.planes)


def test_vtk_files_read_in_pyvista(tmp_path):
    pyvista = pytest.importorskip("pyvista")
    scene = materials_scene(3)
    vtk.write_vtk(scene, tmp_path / "vtk")
    grid = pyvista.read(tmp_path / "vtk" / "spheres_00004.vtu")
    assert_close(T(np.asarray(grid.points)), T(scene.pos[4]), rtol=0, atol=0)
    assert_close(T(np.asarray(grid.point_data["radius"])), T(scene.radius), rtol=0, atol=0)
    planes = pyvista.read(tmp_path / "vtk" / "planes.vtu")
    assert planes.n_cells == len(scene.planes)
