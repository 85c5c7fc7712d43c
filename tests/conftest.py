"""Shared pytest fixtures."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import subprocess
from pathlib import Path

import pytest
import torch
from hydra.core.hydra_config import HydraConfig

from physgnn import CONF_DIR


def compose_generate(overrides: list[str]):
    """The ``generate`` config (conf/generate.yaml) with Hydra ``overrides``."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose("generate", overrides=overrides)


@pytest.fixture(autouse=True)
def fresh_dynamo(request):
    """A slow test starts with dynamo's caches and recompile counts empty: they are per
    process, so the compiles of an earlier test (the same code objects, other modules) would
    count against this one's limit and leave its regions eager."""
    if request.node.get_closest_marker("slow"):
        torch._dynamo.reset()
    yield


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """The ``tiny`` preset generated once per session; returns its folder (train.h5, val.h5,
    test.h5, ood.h5, stats.json). Read-only: copy it before changing anything."""
    from physgnn.groundtruth.generate import generate

    outputs = tmp_path_factory.mktemp("outputs")
    cfg = compose_generate(["data=tiny", f"paths.outputs={outputs}", "workers=1", "progress=false"])
    return generate(cfg)


def _tiny_training(tiny_dataset, run_dir: Path, *extra: str) -> Path:
    """A real run on the ``tiny`` preset (M = 1, 16 hidden units, one epoch of two batches)
    with the ``extra`` overrides, in ``run_dir``."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from physgnn.training.train import train

    overrides = [
        "data=tiny",
        f"data.dir={tiny_dataset}",
        f"run_dir={run_dir}",
        "debug=short",
        "model.network.M=1",
        "model.network.hidden=16",
        "trainer.max_epochs=1",
        "datamodule.pairs_per_epoch=8",
        "trainer.enable_progress_bar=false",
        "trainer.enable_model_summary=false",
        *extra,
    ]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("train", overrides=overrides)
    train(cfg)
    # train() keeps the config where load_run looks, also without Hydra's output folder
    assert OmegaConf.load(run_dir / ".hydra" / "config.yaml").model.network.M == 1
    return run_dir


@pytest.fixture(scope="session")
def tiny_run(tiny_dataset, tmp_path_factory) -> Path:
    """A real run of the default model on the ``tiny`` preset: its checkpoints and
    ``.hydra/config.yaml``, as ``python -m physgnn.train`` leaves them. Read-only."""
    return _tiny_training(tiny_dataset, tmp_path_factory.mktemp("tiny_run"))


@pytest.fixture(scope="session")
def tiny_fd_run(tiny_dataset, tmp_path_factory) -> Path:
    """:func:`tiny_run` of the default before the engine state (finite-difference velocities,
    the planes answering with the pairs): what runs of an earlier layout hold. Read-only."""
    extra = ("model.inputs.engine_state=false", "model.contacts.plane_floor=false")
    return _tiny_training(tiny_dataset, tmp_path_factory.mktemp("tiny_fd_run"), *extra)


@pytest.fixture(scope="session")
def tiny_train(tiny_dataset):
    """The ``tiny`` preset's training split and its statistics: ``(trajectories, stats)``.
    Read-only."""
    from physgnn.data.dataset import read_split

    stats = json.loads((tiny_dataset / "stats.json").read_text())
    return read_split(tiny_dataset / "train.h5"), stats


@pytest.fixture(autouse=True)
def hydra_leaves_nothing_behind():
    """An in-process Hydra ``main`` gives the root logger handlers on this test's captured
    streams and keeps its config: both are put back after each test."""
    handlers, level = logging.root.handlers[:], logging.root.level
    yield
    logging.root.handlers[:] = handlers
    logging.root.setLevel(level)
    HydraConfig.instance().cfg = None


@pytest.fixture
def one_thread():
    """One torch thread, restored afterwards: on the shared 2-core machine two threads made
    small networks ~10x slower (oversubscription), and results are pinned with one."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@contextlib.contextmanager
def mounted_tmpfs(mount: Path, options: str):
    """A real tmpfs mounted on ``mount`` with ``options`` (e.g. ``size=2m``), unmounted after;
    the test is skipped with the reason where it cannot be mounted (root only)."""
    if os.geteuid() != 0 or not shutil.which("mount"):
        pytest.skip("mounting a tmpfs needs root")
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(mount)], capture_output=True
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.decode().strip()})")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=False)
