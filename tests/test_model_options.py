"""The simulator's two option groups (physgnn/models/options.py): one YAML node each, with
exactly their fields, and a value out of range refused in one line naming the key."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from physgnn import CONF_DIR
from physgnn.cli import compose_config
from physgnn.errors import ConfigError
from physgnn.models.learned import LearnedSimulator
from physgnn.models.options import ContactHandling, ModelInputs
from physgnn.nn.epd import EncodeProcessDecode
from physgnn.training.checks import check_arguments

BASELINE = Path(CONF_DIR) / "model" / "baseline.yaml"
GROUPS = {"inputs": ModelInputs, "contacts": ContactHandling}


@pytest.mark.parametrize(("name", "cls"), GROUPS.items())
def test_each_model_group_is_one_node_with_exactly_its_fields(name, cls):
    node = OmegaConf.load(BASELINE)[name]
    assert node._target_ == f"{cls.__module__}.{cls.__name__}"
    assert [k for k in node if k != "_target_"] == [f.name for f in dataclasses.fields(cls)]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda: ModelInputs(boundary_radius=0),
            "model.inputs.boundary_radius must be a number > 0",
        ),
        (lambda: ModelInputs(mass_ratio="no"), "model.inputs.mass_ratio must be true or false"),
        (
            lambda: ContactHandling(rest_speed=-0.01),
            "model.contacts.rest_speed must be a number > 0",
        ),
        (
            lambda: ContactHandling(contact_passes=-1),
            "model.contacts.contact_passes must be a whole number >= 0",
        ),
        (lambda: ContactHandling(contact_passes=1.5), "model.contacts.contact_passes must be"),
        (lambda: ContactHandling(gravity_prior=1), "model.contacts.gravity_prior must be true"),
    ],
)
def test_a_value_out_of_range_is_one_line_naming_the_key(make, message):
    with pytest.raises(ConfigError, match=message) as err:
        make()
    assert "\n" not in str(err.value) and isinstance(err.value, ValueError)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("model.contacts.contact_passes=-1", "^model.contacts.contact_passes must be a whole"),
        ("model.inputs.boundary_radius=0", "^model.inputs.boundary_radius must be a number > 0"),
        ("+model.contacts.passes=1", "^model.contacts.passes is not an argument of Contact"),
    ],
)
def test_a_train_config_out_of_range_is_refused_before_anything_is_built(override, message):
    with pytest.raises(ConfigError, match=message):
        check_arguments(compose_config("train", [override]))


def test_the_constructors_take_at_most_ten_arguments():
    for cls in (LearnedSimulator, EncodeProcessDecode):
        assert len(inspect.signature(cls).parameters) <= 10, cls.__name__
