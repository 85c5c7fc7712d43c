"""Generation in shards (physgnn.groundtruth.shards): two shards of the tiny preset through the
joblib launcher make the one-process dataset byte for byte; a merge refuses a missing shard or
one of another config in one line; a shard written again is kept."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import compose_generate

import physgnn.groundtruth.generate as gen
from physgnn import generate as generate_command
from physgnn.data.dataset import DATASET_MARKER
from physgnn.errors import ConfigError
from physgnn.groundtruth.shards import MANIFEST, ShardError

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = [*gen.FILES, DATASET_MARKER]


def cfg(outputs, *extra):
    return compose_generate(
        ["data=tiny", f"paths.outputs={outputs}", "workers=1", "progress=false", *extra]
    )


def contents(path: Path) -> dict:
    """Every group's and dataset's attributes and every dataset's values, by name."""
    out = {}

    def add(name, obj):
        out[name] = (dict(obj.attrs), obj[()] if isinstance(obj, h5py.Dataset) else None)

    with h5py.File(path) as f:
        add("/", f)
        f.visititems(add)
    return out


def assert_same_contents(a: Path, b: Path) -> None:
    ca, cb = contents(a), contents(b)
    assert list(ca) == list(cb)
    for name in ca:
        (attrs_a, data_a), (attrs_b, data_b) = ca[name], cb[name]
        assert list(attrs_a) == list(attrs_b), name
        for key in attrs_a:
            np.testing.assert_array_equal(attrs_a[key], attrs_b[key], err_msg=f"{name}:{key}")
        if data_a is not None:
            assert data_a.dtype == data_b.dtype
            np.testing.assert_array_equal(data_a, data_b, err_msg=name)


def sweep(outputs: Path, *args: str) -> subprocess.CompletedProcess:
    """``python -m physgnn.generate -m`` of the tiny preset in two shards, one job each."""
    cmd = [
        sys.executable,
        "-m",
        "physgnn.generate",
        "-m",
        "data=tiny",
        f"paths.outputs={outputs}",
        "workers=1",
        "progress=false",
        "num_shards=2",
        "shard=range(0,2)",
        *args,
    ]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)


def assert_one_process_dataset(out: Path, tiny_dataset: Path) -> None:
    assert sorted(p.name for p in out.parent.iterdir()) == ["tiny"]  # the shards are gone
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUTS)
    for name in OUTPUTS:  # HDF5 as physgnn writes it holds no time stamps: bytes compare
        assert (out / name).read_bytes() == (tiny_dataset / name).read_bytes(), name
    for split in gen.SPLITS:
        assert_same_contents(out / f"{split}.h5", tiny_dataset / f"{split}.h5")


def test_two_shards_through_joblib_are_the_one_process_dataset_byte_for_byte(
    tiny_dataset, tmp_path
):
    done = sweep(tmp_path, "hydra/launcher=joblib")
    assert done.returncode == 0, done.stderr[-3000:]
    out = tmp_path / "data" / "tiny"
    assert done.stdout.strip().splitlines()[-1] == f"dataset written to {out}"
    assert_one_process_dataset(out, tiny_dataset)


@pytest.mark.slow
def test_two_shards_through_submitit_are_the_one_process_dataset(tiny_dataset, tmp_path):
    """submitit's local executor: the SLURM launcher's, minus SLURM."""
    done = sweep(tmp_path, "hydra/launcher=submitit_local")
    assert done.returncode == 0, done.stderr[-3000:]
    assert_one_process_dataset(tmp_path / "data" / "tiny", tiny_dataset)


@pytest.mark.slow
def test_a_failed_shard_job_ends_the_sweep_in_one_line_naming_it(tmp_path):
    in_the_way = tmp_path / "data" / "tiny.shards" / "shard-1-of-2"
    in_the_way.mkdir(parents=True)
    (in_the_way / "notes.txt").write_text("mine")
    done = sweep(tmp_path, "hydra/launcher=joblib")
    assert done.returncode == 1  # as a train sweep with a failed job; no merge is tried
    errors = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 2 and "Traceback" not in done.stderr
    assert errors[0].endswith("(this job failed; the sweep goes on)")
    assert errors[1].startswith("error: 1 job(s) of the sweep failed (their errors above; logs in")
    assert (in_the_way / "notes.txt").read_text() == "mine"
    assert not (tmp_path / "data" / "tiny").exists()


def test_shards_merged_in_process_hold_every_trajectory_once(tiny_dataset, tmp_path):
    shards = [gen.generate(cfg(tmp_path, f"shard={i}", "num_shards=3")) for i in range(3)]
    assert [p.name for p in shards] == ["shard-0-of-3", "shard-1-of-3", "shard-2-of-3"]
    held = [json_of(p)["trajectories"] for p in shards]
    # plan: train 0 1, val 0, test 0, ood 0..3; shard 1 of 3 takes plan entries 1, 4, 7
    assert [t[:2] for t in held[1]] == [
        ["train", "traj_00001"],
        ["ood", "ood_cubes"],
        ["ood", "ood_spaced_drop"],
    ]
    assert sorted(map(tuple, sum(held, []))) == sorted(
        (j.split, j.group, j.seed) for j in gen.plan(cfg(tmp_path).data, {})
    )
    assert gen.written(shards[0]).startswith(f"shard 0 of 3 written to {shards[0]}")
    out = gen.generate(cfg(tmp_path, "merge=true", "num_shards=3"))
    for name in OUTPUTS:
        assert (out / name).read_bytes() == (tiny_dataset / name).read_bytes(), name
    assert sorted(p.name for p in out.parent.iterdir()) == ["tiny"]


def json_of(folder: Path) -> dict:
    return json.loads((folder / MANIFEST).read_text())


def test_a_missing_shard_is_one_line_and_nothing_is_written(tmp_path):
    gen.generate(cfg(tmp_path, "shard=0", "num_shards=2"))
    root = tmp_path / "data" / "tiny.shards"
    with pytest.raises(ShardError, match=f"shard 1 of 2 missing in {root} .*then merge again$"):
        gen.generate(cfg(tmp_path, "merge=true", "num_shards=2"))
    with pytest.raises(ShardError, match="holds shards of num_shards=2$"):
        gen.generate(cfg(tmp_path, "merge=true", "num_shards=3"))
    assert sorted(p.name for p in (tmp_path / "data").iterdir()) == ["tiny.shards"]
    assert sorted(p.name for p in root.iterdir()) == [DATASET_MARKER, "shard-0-of-2"]


def test_a_shard_of_another_config_is_refused_by_the_merge(tmp_path):
    gen.generate(cfg(tmp_path, "shard=0", "num_shards=2", "data.seed=5"))
    gen.generate(cfg(tmp_path, "shard=1", "num_shards=2"))
    with pytest.raises(
        ShardError,
        match=r"shard 0 of 2 \(.*\) was made with another config "
        r"\(data.seed: 5 there, 0 here\): merge with",
    ):
        gen.generate(cfg(tmp_path, "merge=true", "num_shards=2"))
    assert not (tmp_path / "data" / "tiny").exists()


def test_a_shard_written_again_is_kept_another_configs_replaced_only_with_overwrite(
    tmp_path, capsys
):
    folder = gen.generate(cfg(tmp_path, "shard=1", "num_shards=2"))
    before = {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}
    assert gen.generate(cfg(tmp_path, "shard=1", "num_shards=2")) == folder
    assert "shard 1 of 2: kept" in capsys.readouterr().out
    assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir()} == before
    with pytest.raises(
        ShardError,
        match=r"was made with another config \(data.splits.train: "
        r"2 there, 3 here\): pass overwrite=true",
    ):
        gen.generate(cfg(tmp_path, "shard=1", "num_shards=2", "data.splits.train=3"))
    gen.generate(cfg(tmp_path, "shard=1", "num_shards=2", "data.splits.train=3", "overwrite=true"))
    assert json_of(folder)["config"]["data"]["splits"]["train"] == 3


def test_a_shard_is_refused_at_once_where_a_dataset_is(tiny_dataset):
    outputs = tiny_dataset.parents[1]
    with pytest.raises(FileExistsError, match="already exists .*pass overwrite=true"):
        gen.generate(cfg(outputs, "shard=0", "num_shards=2"))
    assert not (outputs / "data" / "tiny.shards").exists()


@pytest.mark.parametrize(
    "overrides,message",
    [
        (["shard=1"], "shard=1 needs num_shards=N, the number of shards in all"),
        (["num_shards=2"], "num_shards=2 needs shard=i (0 to 1) to write one shard, or merge="),
        (["num_shards=2", "shard=2"], "shard must be a whole number from 0 to 1, got 2"),
        (["num_shards=0", "shard=0"], "num_shards must be a whole number >= 1, got 0"),
        (["merge=true"], "merge=true needs num_shards=N, the number of shards to assemble"),
        (["num_shards=2", "shard=0", "merge=true"], "merge=true assembles every shard: drop "),
        (["num_shards=9", "shard=0"], "num_shards=9 but data=tiny has 8 trajectories: choose"),
    ],
)
def test_shard_keys_are_checked_in_one_line(tmp_path, overrides, message):
    with pytest.raises(ConfigError) as err:
        gen.generate(cfg(tmp_path, *overrides))
    assert str(err.value).startswith(message)
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").iterdir())


def test_a_shard_key_mistake_on_the_command_line_is_one_line(tmp_path, monkeypatch, capsys):
    argv = ["physgnn.generate", "data=tiny", f"paths.outputs={tmp_path}", "shard=0"]
    monkeypatch.setattr(sys, "argv", [*argv, f"hydra.run.dir={tmp_path}/logs"])
    with pytest.raises(SystemExit) as exit_info:
        generate_command.main()
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: shard=0 needs num_shards=N, the number of shards in all"]


def test_the_end_of_a_sweep_merges_only_a_sweep_over_every_shard(tmp_path):
    gen.generate(cfg(tmp_path, "shard=0", "num_shards=2"))
    sweep = cfg(tmp_path, "num_shards=2")  # a sweep's own config: shard is the jobs'
    assert gen.after_sweep(sweep, {"data": ["tiny"]}) is None  # no shards swept
    some = gen.after_sweep(sweep, {"shard": [0]})
    assert "not merged (shard 1 of 2 not in this sweep)" in some
    varied = gen.after_sweep(sweep, {"shard": [0, 1], "data.seed": [0, 1]})
    assert "not merged (the sweep varied data.seed too)" in varied
    with pytest.raises(ShardError, match="shard 1 of 2 missing"):  # shard 1's job failed
        gen.after_sweep(sweep, {"shard": [0, 1]})
    gen.generate(cfg(tmp_path, "shard=1", "num_shards=2"))
    out = tmp_path / "data" / "tiny"
    assert gen.after_sweep(sweep, {"shard": [0, 1]}) == f"dataset written to {out}"


def test_shards_started_together_share_their_folder_a_foreign_one_is_refused(tmp_path):
    root = tmp_path / "a" / "data" / "tiny.shards"
    root.mkdir(parents=True)  # made by a shard started at the same moment, not marked yet
    folder = gen.generate(cfg(tmp_path / "a", "shard=0", "num_shards=2"))
    assert (folder / MANIFEST).is_file()
    foreign = tmp_path / "b" / "data" / "tiny.shards"
    foreign.mkdir(parents=True)
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match=r"holds files that physgnn did not write \(notes"):
        gen.generate(cfg(tmp_path / "b", "shard=0", "num_shards=2"))
    assert [p.name for p in foreign.iterdir()] == ["notes.txt"]


def test_a_killed_shards_lock_and_staging_folder_are_not_taken_for_shards(tmp_path):
    gen.generate(cfg(tmp_path, "shard=0", "num_shards=2"))
    root = tmp_path / "data" / "tiny.shards"
    (root / "shard-1-of-2.lock").write_text("pid 1 on a host that died")  # a killed shard's
    (root / "shard-1-of-2.staging-123").mkdir()
    with pytest.raises(ShardError, match=f"shard 1 of 2 missing in {root} .*then merge again$"):
        gen.generate(cfg(tmp_path, "merge=true", "num_shards=2"))
    with pytest.raises(ShardError, match="holds shards of num_shards=2$"):
        gen.generate(cfg(tmp_path, "merge=true", "num_shards=3"))
