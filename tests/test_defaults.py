"""One source of truth: every literal value of the training recipe's nodes
(``conf/lit/default.yaml``: ``lit.scheduler``; the groups ``lit.noise`` ... with exactly their
dataclass's fields) and of the training data's recipe (``conf/datamodule/default.yaml``) equals
the default of the constructor argument of that name (interpolations such as ``${seed}`` and
nested nodes such as the optimiser are the config's alone)."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from physgnn import CONF_DIR
from physgnn.training.callbacks import RolloutCallback
from physgnn.training.datamodule import StatePairDataModule
from physgnn.training.lit import LitSimulator
from physgnn.training.recipe import Compile, InputNoise, LossTerms, PushForward
from physgnn.training.schedule import RunLengthDecay

TRAIN = Path(CONF_DIR) / "train.yaml"
RECIPE = Path(CONF_DIR) / "lit" / "default.yaml"
DATA_RECIPE = Path(CONF_DIR) / "datamodule" / "default.yaml"
GROUPS = {"noise": InputNoise, "pushforward": PushForward, "loss": LossTerms, "compile": Compile}


def literal_values(node) -> dict:
    """The keys of a config node whose value is a plain value, not an interpolation or node."""
    out = {}
    for key in node:
        if key.startswith("_") or OmegaConf.is_interpolation(node, key):
            continue
        value = node[key]
        if not OmegaConf.is_config(value):
            out[key] = value
    return out


@pytest.mark.parametrize(
    ("path", "node", "cls"),
    [(RECIPE, "scheduler", RunLengthDecay), (DATA_RECIPE, "", StatePairDataModule)]
    + [(RECIPE, name, cls) for name, cls in GROUPS.items()],
)
def test_constructor_defaults_equal_the_yaml(path, node, cls):
    cfg = OmegaConf.select(OmegaConf.load(path), node)
    params = inspect.signature(cls).parameters
    literals = literal_values(cfg)
    assert literals, f"{node} has no literal value to compare"
    for key, value in literals.items():
        assert key in params, f"{node}.{key} is no argument of {cls.__name__}"
        assert params[key].default == value, (
            f"{node}.{key}: code {params[key].default}, YAML {value}"
        )


@pytest.mark.parametrize(("name", "cls"), GROUPS.items())
def test_each_recipe_group_is_one_node_with_exactly_its_fields(name, cls):
    node = OmegaConf.load(RECIPE)[name]
    assert node._target_ == f"{cls.__module__}.{cls.__name__}"
    assert [k for k in node if k != "_target_"] == [f.name for f in dataclasses.fields(cls)]
    assert inspect.signature(LitSimulator).parameters[name].default == cls()


def test_the_rollout_callback_defaults_equal_its_yaml_and_the_default_preset():
    conf = TRAIN.parent
    node = OmegaConf.load(conf / "callbacks" / "default.yaml").rollout
    preset = OmegaConf.load(conf / "data" / "small.yaml").val_rollout
    expected = literal_values(node) | {
        "n_val_trajectories": preset.trajectories,
        "max_frames": preset.frames,
    }
    params = inspect.signature(RolloutCallback).parameters
    assert {key: params[key].default for key in expected} == expected
