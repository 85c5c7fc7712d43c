"""`python -m physgnn.generate` on the tiny preset (physgnn.generate)."""

from __future__ import annotations

import json
import shutil
import sys

import h5py
import numpy as np
import pytest
from conftest import compose_generate

import physgnn.generate as generate_command
import physgnn.groundtruth.generate as gen
from physgnn.api import scene_of
from physgnn.data.dataset import DATASET_MARKER, SCHEMA_VERSION, read_split
from physgnn.data.stats import compute_stats, read_stats
from physgnn.errors import Interrupted
from physgnn.groundtruth.engine import simulate
from physgnn.physics.scene import SceneError
from physgnn.physics.trajectory import FRAME_KEYS

SPLIT_SIZES = {"train": 2, "val": 1, "test": 1}
OOD = ["ood_cubes", "ood_cubes_ramps", "ood_resting_hit", "ood_spaced_drop"]


def tiny_cfg(outputs, *extra):
    return compose_generate(["data=tiny", f"paths.outputs={outputs}", "progress=false", *extra])


def test_tiny_dataset_files_and_schema(tiny_dataset):
    assert sorted(p.name for p in tiny_dataset.parent.iterdir()) == ["tiny"]  # no leftovers
    assert sorted(p.name for p in tiny_dataset.iterdir()) == sorted([*gen.FILES, DATASET_MARKER])
    for split in ("train", "val", "test", "ood"):
        with h5py.File(tiny_dataset / f"{split}.h5") as f:
            assert f.attrs["schema_version"] == SCHEMA_VERSION
            assert f.attrs["split"] == split and f.attrs["preset"] == "tiny"
            names = sorted(f)
        if split == "ood":
            assert names == OOD
        else:
            assert names == [f"traj_{i:05d}" for i in range(SPLIT_SIZES[split])]
    trajs = read_split(tiny_dataset / "ood.h5")
    for traj in trajs:
        assert traj.attrs["scene"] == traj.name and traj.n_frames == 20
        assert traj.attrs["engine"].startswith("pybullet") and traj.attrs["substeps"] == 40
        assert f"name: {traj.name}" in traj.attrs["scene_config"]
    train = read_split(tiny_dataset / "train.h5")
    assert [t.attrs["seed"] for t in train] == [gen.trajectory_seed(0, "train", i) for i in (0, 1)]
    assert 2 <= train[0].n_spheres <= 3
    stats = read_stats(tiny_dataset)
    expected = compute_stats(train)
    assert stats["n_pairs"] == expected["n_pairs"] == 2 * 19
    np.testing.assert_allclose(stats["vel"]["std"], expected["vel"]["std"], rtol=1e-12)


def test_every_split_replays_from_its_stored_start(tiny_dataset):
    """What is stored is what was simulated: the engine at the truth's own settings, started
    from the stored frame 0, gives the stored truth again, frame for frame."""
    for split in ("train", "val", "test", "ood"):
        for truth in read_split(tiny_dataset / f"{split}.h5"):
            replay = simulate(scene_of(truth), json.loads(truth.attrs["engine_settings"]))
            for key in FRAME_KEYS:
                np.testing.assert_array_equal(getattr(replay, key), getattr(truth, key))


def test_trajectory_seeds_are_distinct_and_stable():
    seeds = {
        gen.trajectory_seed(0, s, i) for s in ("train", "val", "test", "ood") for i in range(50)
    }
    assert len(seeds) == 200
    assert gen.trajectory_seed(0, "train", 3) == gen.trajectory_seed(0, "train", 3)
    assert gen.trajectory_seed(1, "train", 3) != gen.trajectory_seed(0, "train", 3)


def test_same_seed_same_data_whatever_the_worker_count(tiny_dataset, tmp_path):
    out = gen.generate(tiny_cfg(tmp_path, "workers=2"))
    for split in ("train", "test", "ood"):
        a, b = read_split(tiny_dataset / f"{split}.h5"), read_split(out / f"{split}.h5")
        assert [t.name for t in a] == [t.name for t in b]
        for ta, tb in zip(a, b, strict=True):
            for key in ("pos", "quat", "vel", "angvel", "radius", "mass", "planes"):
                np.testing.assert_array_equal(getattr(ta, key), getattr(tb, key))


def test_refuses_to_overwrite_in_one_line(tiny_dataset, monkeypatch, capsys):
    outputs = tiny_dataset.parents[1]
    with pytest.raises(FileExistsError, match="already exists .*pass overwrite=true"):
        gen.generate(tiny_cfg(outputs, "workers=1"))
    # the command as its console script runs it (its own process: tests/test_faults.py)
    argv = ["physgnn.generate", "data=tiny", f"paths.outputs={outputs}"]
    monkeypatch.setattr(sys, "argv", [*argv, f"hydra.run.dir={outputs}/hydra"])
    with pytest.raises(SystemExit) as exit_info:
        generate_command.main()
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert err.strip().startswith("error: dataset") and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_interrupted_overwrite_leaves_the_previous_dataset(tiny_dataset, tmp_path, monkeypatch):
    outputs = tmp_path / "outputs"
    shutil.copytree(tiny_dataset, outputs / "data" / "tiny")
    before = {p.name: p.read_bytes() for p in (outputs / "data" / "tiny").iterdir()}
    real = gen.run_jobs

    def interrupted(jobs, *args, **kwargs):
        if jobs[0].split == "test":
            raise KeyboardInterrupt
        return real(jobs, *args, **kwargs)

    monkeypatch.setattr(gen, "run_jobs", interrupted)
    with pytest.raises(Interrupted, match="generation stopped by SIGINT") as stopped:
        gen.generate(tiny_cfg(outputs, "workers=1", "overwrite=true", "data.seed=5"))
    assert stopped.value.exit_code == 130
    after = {p.name: p.read_bytes() for p in (outputs / "data" / "tiny").iterdir()}
    assert after == before
    assert sorted(p.name for p in (outputs / "data").iterdir()) == ["tiny"]


def test_overwrite_true_replaces_the_dataset(tiny_dataset, tmp_path):
    outputs = tmp_path / "outputs"
    shutil.copytree(tiny_dataset, outputs / "data" / "tiny")
    out = gen.generate(tiny_cfg(outputs, "workers=1", "overwrite=true", "data.seed=5"))
    new = read_split(out / "val.h5")[0]
    assert new.attrs["seed"] == gen.trajectory_seed(5, "val", 0)
    assert sorted(p.name for p in (outputs / "data").iterdir()) == ["tiny"]


def test_unknown_scene_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError, match="unknown scene 'nope'"):
        gen.generate(tiny_cfg(tmp_path, "workers=1", "data.scene.name=nope"))
    assert not (tmp_path / "data" / "tiny").exists()
