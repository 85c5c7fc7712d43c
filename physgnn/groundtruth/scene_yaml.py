"""YAML as a scene file is read: every number a person writes is a number (YAML 1.2's, as
JSON's), and a key given twice is an error, not the last value silently."""

from __future__ import annotations

import re

import yaml


class SceneLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """``yaml.safe_load`` (libyaml's parser where installed) that reads every number a person
    writes as a number: YAML 1.1 (PyYAML) takes an exponent without a dot or without a sign
    (``1e+01``, ``1e1``, ``1.0e5``) for a string; YAML 1.2 and JSON read a float, and so does
    this loader."""


def _unique_keys(loader: SceneLoader, node: yaml.MappingNode) -> dict:
    """A mapping whose keys are all different: a key given twice (YAML would keep the last
    silently) is an error naming its line."""
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key '{key}' given twice (keep one)", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node, deep=True)


SceneLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_keys)
SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)
