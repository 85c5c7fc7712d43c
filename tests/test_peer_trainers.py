"""The contract the peers' trainers read from an export: GNS's ``train.py`` and LagrangeBench's
runner, each key they read, each file they open and each input width they derive.

Every helper below follows the peer's code it names (geoelements/gns ``gns/train.py``,
``gns/reading_utils.py``, ``gns/data_loader.py``, ``gns/learned_simulator.py``;
tumaer/lagrangebench ``lagrangebench/runner.py``, ``lagrangebench/data/data.py``,
``lagrangebench/data/utils.py``, ``lagrangebench/case_setup/case.py``,
``lagrangebench/models/utils.py``, ``lagrangebench/evaluate/metrics.py``,
``lagrangebench/defaults.py``), reading what they read, as they read it."""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from simdata import trajectory

import physgnn.api as pg
from physgnn.data import interchange

# gns/train.py
GNS_INPUT_SEQUENCE_LENGTH = 6
GNS_NUM_PARTICLE_TYPES = 9
GNS_TYPE_EMBEDDING_SIZE = 16  # _get_simulator: particle_type_embedding_size
GNS_DEFAULT_NNODE_IN = 37  # _get_simulator, dim 3, without a material property
GNS_NOISE_STD = 6.7e-4  # --noise_std
# lagrangebench/defaults.py and lagrangebench/utils.py
LB_INPUT_SEQ_LENGTH = 6
LB_PUSHFORWARD_UNROLLS = [0, 1, 2, 3]
LB_N_ROLLOUT_STEPS = 20
LB_NODE_TYPES = 9  # NodeType.SIZE


def splits(frames: int = 30) -> dict:
    """physgnn's three splits, as a user hands them over (``val``, not ``valid``)."""
    return {
        "train": [trajectory(n=3, frames=frames, seed=s) for s in range(2)],
        "val": [trajectory(n=3, frames=frames, seed=5)],
        "test": [trajectory(n=4, frames=frames, seed=7)],
    }


def gns_read_metadata(data_path: str, purpose: str) -> dict:
    """gns/reading_utils.py read_metadata: ``metadata[purpose]``, else the whole file."""
    with open(os.path.join(data_path, "metadata.json")) as fp:
        metadata = json.loads(fp.read())
    return metadata[purpose] if purpose in metadata else metadata


def gns_load_npz_data(path: str) -> list:
    """gns/data_loader.py load_npz_data."""
    with np.load(path, allow_pickle=True) as data_file:
        if "gns_data" in data_file:
            return data_file["gns_data"]
        return [item for _, item in data_file.items()]


def gns_simulator_arguments(metadata: dict) -> dict:
    """gns/train.py _get_simulator: every key it reads, as it reads it."""
    stats = {k: np.asarray(metadata[k], np.float32) for k in ("acc_mean", "acc_std")}
    stats |= {k: np.asarray(metadata[k], np.float32) for k in ("vel_mean", "vel_std")}
    if "nnode_in" in metadata and "nedge_in" in metadata:
        nnode_in, nedge_in = metadata["nnode_in"], metadata["nedge_in"]
    else:
        nnode_in = 37 if metadata["dim"] == 3 else 30
        nedge_in = metadata["dim"] + 1
    return {
        "stats": stats,
        "particle_dimensions": metadata["dim"],
        "nnode_in": nnode_in,
        "nedge_in": nedge_in,
        "connectivity_radius": metadata["default_connectivity_radius"],
        "boundaries": np.array(metadata["bounds"]),
        "boundary_clamp_limit": metadata.get("boundary_augment", 1.0),
    }


def gns_feature_widths(data_path: str, split: str, metadata: dict) -> tuple[int, int]:
    """The widths of the node and edge features gns/learned_simulator.py
    _encoder_preprocessor builds from one sample of ``<split>.npz`` (data_loader.py
    SamplesDataset.__getitem__): the velocity sequence, the distances to the boundaries, the
    particle type's embedding, the material property when the entry has one; edges: the
    relative displacement and its length."""
    args = gns_simulator_arguments(metadata)
    entry = gns_load_npz_data(f"{data_path}{split}.npz")[0]
    positions = np.transpose(entry[0][:GNS_INPUT_SEQUENCE_LENGTH], (1, 0, 2))
    n = positions.shape[0]
    velocity = np.diff(positions, axis=1)
    std = np.sqrt(args["stats"]["vel_std"] ** 2 + GNS_NOISE_STD**2)
    velocity = (velocity - args["stats"]["vel_mean"]) / std
    nodes = [velocity.reshape(n, -1)]
    last = positions[:, -1]
    bounds = args["boundaries"]
    distances = np.concatenate([last - bounds[:, 0][None], bounds[:, 1][None] - last], axis=1)
    nodes.append(np.clip(distances / args["connectivity_radius"], -1.0, 1.0))
    particle_type = np.full(n, entry[1], dtype=int)
    embedding = np.zeros((GNS_NUM_PARTICLE_TYPES, GNS_TYPE_EMBEDDING_SIZE))
    nodes.append(embedding[particle_type])
    if len(entry) >= 3:  # data_loader: _material_property_as_feature
        nodes.append(np.full(n, entry[2], dtype=float).reshape(n, 1))
    displacement = (last[:, None] - last[None]).reshape(-1, 3) / args["connectivity_radius"]
    edges = [displacement, np.linalg.norm(displacement, axis=-1, keepdims=True)]
    return np.concatenate(nodes, axis=-1).shape[1], np.concatenate(edges, axis=-1).shape[1]


def test_gns_train_py_finds_its_files_and_the_input_widths_of_its_network(tmp_path):
    pg.export(splits(), tmp_path / "gns", "gns")
    data_path = f"{tmp_path / 'gns'}/"  # train.py appends the file names to --data_path
    # train: train.npz; --validation_interval: valid.npz; --mode=rollout: test.npz
    for split in ("train", "valid", "test"):
        assert Path(f"{data_path}{split}.npz").is_file()
    for purpose in ("train", "rollout"):
        metadata = gns_read_metadata(data_path, purpose)
        assert "train" not in metadata and "rollout" not in metadata  # one flat metadata
        args = gns_simulator_arguments(metadata)
        assert args["particle_dimensions"] == 3 and args["boundaries"].shape == (3, 2)
        assert all(v.shape == (3,) and np.isfinite(v).all() for v in args["stats"].values())
        assert args["connectivity_radius"] > 0
        for split in ("train", "valid", "test"):
            widths = gns_feature_widths(data_path, split, metadata)
            assert widths == (args["nnode_in"], args["nedge_in"]) == (38, 4)
    assert GNS_DEFAULT_NNODE_IN == 38 - 1  # why the export writes nnode_in: the material
    assert interchange.gns_widths() == {"nnode_in": 38, "nedge_in": 4}


def test_gns_samples_and_rollout_lengths_are_what_train_py_takes(tmp_path):
    pg.export(splits(frames=12), tmp_path / "gns", "gns")
    data_path = f"{tmp_path / 'gns'}/"
    train = gns_load_npz_data(f"{data_path}train.npz")
    valid = gns_load_npz_data(f"{data_path}valid.npz")
    assert len(train[0]) == len(valid[0]) == 3  # train.py: n_features of valid == train
    for x, particle_type, material_property in train:
        # SamplesDataset: x.shape[0] - INPUT_SEQUENCE_LENGTH samples of each trajectory
        assert x.shape[0] - GNS_INPUT_SEQUENCE_LENGTH >= 1 and x.dtype == np.float32
        assert particle_type.shape == material_property.shape == (x.shape[1],)
    metadata = gns_read_metadata(data_path, "rollout")
    nsteps = metadata["sequence_length"] - GNS_INPUT_SEQUENCE_LENGTH  # predict()
    test = gns_load_npz_data(f"{data_path}test.npz")
    assert all(1 <= nsteps <= x.shape[0] - GNS_INPUT_SEQUENCE_LENGTH for x, _, _ in test)


def lb_h5_dataset(src: Path, split: str, extra_seq_length: int) -> dict:
    """lagrangebench/data/data.py H5Dataset.__init__: the file, its length, the window."""
    assert split in ["train", "valid", "test"]
    with open(src / "metadata.json") as f:
        metadata = json.loads(f.read())
    with h5py.File(src / f"{split}.h5", "r") as f:
        traj_keys = list(f.keys())
        sequence_length = f["00000/position"].shape[0]
        particle_type = f[traj_keys[0]]["particle_type"][:]
    if split == "train":
        subseq_length = LB_INPUT_SEQ_LENGTH + 1 + extra_seq_length
    else:
        subseq_length = LB_INPUT_SEQ_LENGTH + extra_seq_length
    assert sequence_length >= subseq_length
    return {"metadata": metadata, "particle_type": particle_type, "n": len(traj_keys)}


def lb_node_irreps(metadata: dict, homogeneous_particles: bool) -> str:
    """lagrangebench/models/utils.py node_irreps (SEGNN's node inputs), no external force and
    no magnitudes (the defaults)."""
    irreps = [f"{LB_INPUT_SEQ_LENGTH - 1}x1o"]
    if not any(metadata["periodic_boundary_conditions"]):
        irreps.append("2x1o")
    if not homogeneous_particles:
        irreps.append(f"{LB_NODE_TYPES}x0e")
    return "+".join(irreps)


def test_lagrangebench_runner_opens_its_three_splits_and_reads_its_keys(tmp_path):
    pg.export(splits(), tmp_path / "lb", "lagrangebench")
    src = tmp_path / "lb"
    # runner.py setup_data: train (pushforward's last unroll), valid and test (the rollout)
    data_train = lb_h5_dataset(src, "train", LB_PUSHFORWARD_UNROLLS[-1])
    for split in ("valid", "test"):
        lb_h5_dataset(src, split, LB_N_ROLLOUT_STEPS)
    metadata = data_train["metadata"]
    bounds = np.array(metadata["bounds"])  # runner.py: the box
    assert bounds.shape == (3, 2) and (bounds[:, 1] >= bounds[:, 0]).all()
    for key in ("acc_mean", "acc_std", "vel_mean", "vel_std"):  # data/utils.py
        assert np.isfinite(np.asarray(metadata[key], np.float64)).all()
        assert len(metadata[key]) == metadata["dim"] == 3
    assert len(metadata["periodic_boundary_conditions"]) == 3  # case.py, models/utils.py
    assert metadata["default_connectivity_radius"] > 0  # case.py: r_cutoff
    assert metadata["num_particles_max"] == 4  # case.py, data.py: the padding
    assert metadata["dt"] * metadata["write_every"] > 0 and metadata["dx"] > 0  # metrics.py
    particle_type = data_train["particle_type"]  # runner.py: data_train[0]
    homogeneous = particle_type.max() == particle_type.min()
    assert homogeneous and lb_node_irreps(metadata, homogeneous) == "5x1o+2x1o"


# (writer, reader, file suffix) of each peer format
PEERS = {
    "gns": (interchange.write_gns, interchange.read_gns, "npz"),
    "lagrangebench": (interchange.write_lagrangebench, interchange.read_lagrangebench, "h5"),
}


@pytest.mark.parametrize("fmt", list(PEERS))
def test_physgnn_val_is_the_peers_valid_and_reads_back_as_either(tmp_path, fmt):
    write, read, suffix = PEERS[fmt]
    data = splits(frames=8)
    write(tmp_path / fmt, data)
    files = sorted(p.name for p in (tmp_path / fmt).glob(f"*.{suffix}"))
    assert files == [f"{split}.{suffix}" for split in ("test", "train", "valid")]
    for split in ("val", "valid"):
        (back,) = read(tmp_path / fmt, split, radius=data["val"][0].radius)
        np.testing.assert_array_equal(back.pos, data["val"][0].pos)
        np.testing.assert_array_equal(back.materials, data["val"][0].materials)


def test_a_gns_export_written_with_val_npz_still_imports(tmp_path):
    data = splits(frames=8)
    interchange.write_gns(tmp_path / "gns", data)
    folder = tmp_path / "gns"  # as exports wrote it before: val.npz, its tables under "val"
    os.replace(folder / "valid.npz", folder / "val.npz")
    meta = json.loads((folder / "metadata.json").read_text())
    meta["materials"]["val"] = meta["materials"].pop("valid")
    (folder / "metadata.json").write_text(json.dumps(meta))
    for split in ("val", "valid"):
        (back,) = interchange.read_gns(folder, split, radius=data["val"][0].radius)
        np.testing.assert_array_equal(back.pos, data["val"][0].pos)
        np.testing.assert_array_equal(back.materials, data["val"][0].materials)
