"""Shared pytest fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def compose_generate(overrides: list[str]):
    """The ``generate`` config (conf/generate.yaml) with Hydra ``overrides``."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose("generate", overrides=overrides)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    """The ``tiny`` preset generated once per session; returns its folder (train.h5, val.h5,
    test.h5, ood.h5, stats.json). Read-only: copy it before changing anything."""
    from physgnn.groundtruth.generate import generate

    outputs = tmp_path_factory.mktemp("outputs")
    cfg = compose_generate(["data=tiny", f"paths.outputs={outputs}", "workers=1", "progress=false"])
    return generate(cfg)
