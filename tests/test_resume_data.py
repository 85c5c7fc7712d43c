"""A resume trains on the dataset its run started on: another one at the folder's path (another
seed, another PHYSGNN_OUTPUTS) is refused in one line naming both, before anything is written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from physgnn.errors import ConfigError
from physgnn.training.datamodule import dataset_identity
from physgnn.training.resume_checks import check_run_dir


def dataset(folder: Path, seed: int) -> Path:
    """What dataset_identity reads of a dataset: stats.json and the sizes of the splits."""
    folder.mkdir(parents=True)
    (folder / "stats.json").write_text(json.dumps({"seed": seed}))
    for name in ("train.h5", "val.h5"):
        (folder / name).write_bytes(b"\0" * (100 + seed))
    return folder


def interrupted_run(run_dir: Path, data: Path) -> Path:
    (run_dir / "checkpoints").mkdir(parents=True)
    (run_dir / "checkpoints" / "last.ckpt").write_bytes(b"weights")
    info = {"status": "interrupted", "dataset": dataset_identity(data, "tiny"), "overrides": []}
    (run_dir / "run.json").write_text(json.dumps(info))
    return run_dir


def config(data: Path, ckpt_path: str | None = None):
    return OmegaConf.create({"datamodule": {"data_dir": str(data)}, "ckpt_path": ckpt_path})


def test_a_resume_on_another_dataset_is_refused_naming_both(tmp_path):
    first, second = dataset(tmp_path / "a" / "tiny", 0), dataset(tmp_path / "b" / "tiny", 7)
    run = interrupted_run(tmp_path / "run", first)
    before = (run / "run.json").read_text()
    check_run_dir(config(first), run)  # the same dataset: resumed
    with pytest.raises(ConfigError) as err:
        check_run_dir(config(second), run)
    then = dataset_identity(first, "tiny")["sha256"][:12]
    now = dataset_identity(second, "tiny")["sha256"][:12]
    assert str(err.value) == (
        f"run_dir {run} resumes a run trained on another dataset: {first} (sha256 {then}) "
        f"then, {second} (sha256 {now}) now: resume with the dataset it was trained on (data=, "
        f"data.dir=, PHYSGNN_OUTPUTS as then), or train on from its weights in a new run_dir "
        f"(ckpt_path={run / 'checkpoints' / 'last.ckpt'} run_dir=<a new folder>)"
    )
    assert (run / "run.json").read_text() == before


def test_a_run_of_an_earlier_physgnn_without_a_hash_resumes(tmp_path):
    data = dataset(tmp_path / "tiny", 0)
    run = interrupted_run(tmp_path / "run", data)
    earlier = json.dumps({"status": "interrupted", "overrides": []})
    (run / "run.json").write_text(earlier)
    check_run_dir(config(data), run)  # no dataset hash to compare: resumed, nothing refused
    assert (run / "run.json").read_text() == earlier  # and the earlier record left as it was
