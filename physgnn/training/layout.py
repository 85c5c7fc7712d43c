"""The model config of a run on disk in this physgnn's layout: the one place where the model
configs of earlier runs (``.hydra/config.yaml``, the shipped ``physgnn/pretrained``) are read
into today's.

Today's layout (``conf/model/baseline.yaml``) nests the network and the graph builder in nodes
of their own, ``model.network`` and ``model.graph``, each built by Hydra from its ``_target_``.
Runs of an earlier physgnn hold them as flat keys of ``model`` (``model.M``,
``model.connectivity``, ``model.neighbor_backend``): :func:`model_of_today` moves them.
"""

from __future__ import annotations

from omegaconf import DictConfig, OmegaConf

# Model targets of runs trained before the package was split into subpackages.
MOVED_TARGETS = {"physgnn.simulator.LearnedSimulator": "physgnn.models.learned.LearnedSimulator"}
# Model keys that runs of an earlier physgnn lack, with the values their model had (the
# invariance changes: physgnn/models/learned.py); the defaults of these keys changed since.
EARLIER_MODEL = {
    "relative_pairs": False,
    "mass_ratio": False,
    "aggregation": "sum",
    "rest_decision": False,
    "fixed_capacity": False,
}
# Model keys that runs before the contact changes lack, with the values their model had
# (physgnn/models/learned.py: contacts within the frame, pair impulses, the latch, plane
# materials).
PREVIOUS_MODEL = {
    "contact_passes": 0,
    "pair_impulses": False,
    "recent_contact": True,
    "plane_materials": False,
    "contact_memory": False,
}
LEARNED = "physgnn.models.learned.LearnedSimulator"
# The nodes of today's layout, with the Hydra keys that build them.
NODES = {
    "network": {"_target_": "physgnn.nn.epd.EncodeProcessDecode", "_partial_": True},
    "graph": {"_target_": "physgnn.graph.builder.GraphBuilder"},
}
# Each flat model key of an earlier run: its node and its name there.
FLAT_KEYS = {
    "hidden": ("network", "hidden"),
    "M": ("network", "M"),
    "third_law": ("network", "third_law"),
    "use_surfaces": ("network", "use_surfaces"),
    "num_materials": ("network", "num_materials"),
    "material_dim": ("network", "material_dim"),
    "layer_norm": ("network", "layer_norm"),
    "aggregation": ("network", "aggregation"),
    "connectivity": ("graph", "connectivity"),
    "epsilon": ("graph", "epsilon"),
    "factor": ("graph", "factor"),
    "neighbor_backend": ("graph", "backend"),
    "clip_margin": ("graph", "clip_margin"),
    "fixed_capacity": ("graph", "fixed_capacity"),
}


def model_of_today(model: DictConfig) -> DictConfig:
    """``model`` (a run's ``model`` node) in today's layout: a moved target renamed; a flat
        model (no ``network`` node: an earlier physgnn's) with the keys it lacks at its own model's
        values (:data:`EARLIER_MODEL`) and its network and graph keys moved into their nodes
        (:data:`FLAT_KEYS`); a learned simulator without the keys of the contact changes with its
    own model's values (:data:`PREVIOUS_MODEL`). A model of today's layout comes back as it is."""
    flat = OmegaConf.to_container(model, resolve=False)
    if flat.get("_target_") in MOVED_TARGETS:
        flat["_target_"] = MOVED_TARGETS[flat["_target_"]]
    if "network" not in flat:
        flat = EARLIER_MODEL | flat
        nested = {k: v for k, v in flat.items() if k not in FLAT_KEYS}
        nested |= {node: dict(keys) for node, keys in NODES.items()}
        for key, (node, name) in FLAT_KEYS.items():
            if key in flat:
                nested[node][name] = flat[key]
        flat = nested
    if flat.get("_target_") == LEARNED:
        flat = PREVIOUS_MODEL | flat
    return OmegaConf.create(flat)


def key_of_today(key: str) -> str:
    """``"model.M=1"`` → ``"model.network.M=1"``: a dotted key (or ``key=value``) of the flat
    layout in today's; any other key comes back as it is."""
    name, sep, value = key.partition("=")
    if name.startswith("model.") and name.count(".") == 1 and name[6:] in FLAT_KEYS:
        name = "model." + ".".join(FLAT_KEYS[name[6:]])
    return name + sep + value


def flat_layout(keys: dict) -> dict:
    """``{dotted key: value}`` of a composed config with its model keys in the flat layout
    (``model.network.M`` → ``model.M``, the nodes' Hydra keys dropped): the inverse of
    :func:`key_of_today`, so that what names a configuration does not change with its
    spelling."""
    before = {f"model.{node}.{name}": f"model.{key}" for key, (node, name) in FLAT_KEYS.items()}
    hydra = {f"model.{node}.{key}" for node, keys in NODES.items() for key in keys}
    return {before.get(k, k): v for k, v in keys.items() if k not in hydra}


def dotted_model(model: DictConfig) -> dict:
    """``{"H": 2, "network.M": 5, ...}``: a model config's keys, those of its nodes dotted."""
    out = {}
    for key, value in OmegaConf.to_container(model, resolve=True).items():
        if isinstance(value, dict):
            out |= {f"{key}.{k}": v for k, v in value.items()}
        else:
            out[key] = value
    return out
