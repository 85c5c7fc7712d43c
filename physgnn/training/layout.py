"""The model config of a run on disk in this physgnn's layout: the one place where the model
configs of earlier runs (``.hydra/config.yaml``, the shipped ``physgnn/pretrained``) are read
into today's.

Today's layout (``conf/model/baseline.yaml``) nests the network, the graph builder and the
simulator's two groups of options in nodes of their own, ``model.network``, ``model.graph``,
``model.inputs`` and ``model.contacts`` (:mod:`physgnn.models.options`), each built by Hydra
from its ``_target_``. Runs of an earlier physgnn hold them as flat keys of ``model``
(``model.M``, ``model.connectivity``, ``model.neighbor_backend``, ``model.contact_passes``):
:func:`model_of_today` moves them, and a flat key of the simulator's groups typed on today's
command line is refused naming its new spelling (:func:`check_renamed`).

Likewise the training recipe: today's ``lit`` holds four groups (``lit.noise``,
``lit.pushforward``, ``lit.loss``, ``lit.compile``: :mod:`physgnn.training.recipe`) and its
scheduler decays by ``decay_per_epoch`` over ``epochs``; earlier runs hold flat keys
(``lit.noise_std``) and a ``final_lr_factor``: :func:`lit_of_today` moves them, and a flat key
typed on today's command line is refused naming its new spelling (:func:`check_renamed`).
"""

from __future__ import annotations

from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError
from physgnn.overrides import parse_override, parse_overrides

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
# Keys that runs before the engine state, the planes by Newton's law, the pairs' floor or the
# pairs by Newton's law lack, per node, with the value their model had.
BEFORE_ENGINE_STATE = {
    "inputs": {"engine_state": False},
    "contacts": {
        "plane_floor": False,
        "plane_newton": False,
        "pair_floor": False,
        "pair_newton": False,
    },
}
LEARNED = "physgnn.models.learned.LearnedSimulator"
# The nodes of today's layout, with the Hydra keys that build them.
NODES = {
    "network": {"_target_": "physgnn.nn.epd.EncodeProcessDecode", "_partial_": True},
    "graph": {"_target_": "physgnn.graph.builder.GraphBuilder"},
    "inputs": {"_target_": "physgnn.models.options.ModelInputs"},
    "contacts": {"_target_": "physgnn.models.options.ContactHandling"},
}
# The simulator's groups (physgnn/models/options.py): their flat keys are refused on a command
# line (check_renamed), as the recipe's are.
MODEL_GROUPS = ("inputs", "contacts")
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
    "boundary_features": ("inputs", "boundary_features"),
    "boundary_radius": ("inputs", "boundary_radius"),
    "contact_features": ("inputs", "contact_features"),
    "material_features": ("inputs", "material_features"),
    "relative_pairs": ("inputs", "relative_pairs"),
    "mass_ratio": ("inputs", "mass_ratio"),
    "plane_materials": ("inputs", "plane_materials"),
    "gravity_prior": ("contacts", "gravity_prior"),
    "contact_passes": ("contacts", "contact_passes"),
    "pair_impulses": ("contacts", "pair_impulses"),
    "rest_decision": ("contacts", "rest_decision"),
    "rest_speed": ("contacts", "rest_speed"),
    "recent_contact": ("contacts", "recent_contact"),
    "contact_memory": ("contacts", "contact_memory"),
    "engine_state": ("inputs", "engine_state"),
    "plane_floor": ("contacts", "plane_floor"),
    "plane_newton": ("contacts", "plane_newton"),
    "pair_floor": ("contacts", "pair_floor"),
    "pair_newton": ("contacts", "pair_newton"),
    "incremental_passes": ("contacts", "incremental_passes"),
    "energy_guard": ("contacts", "energy_guard"),
    "energy_slack": ("contacts", "energy_slack"),
    "friction_cone": ("contacts", "friction_cone"),
    "rest_consistent": ("contacts", "rest_consistent"),
}


RECIPE = "physgnn.training.recipe"
# The recipe's groups of today (conf/lit/default.yaml), with the Hydra keys that build them.
LIT_NODES = {
    "noise": {"_target_": f"{RECIPE}.InputNoise"},
    "pushforward": {"_target_": f"{RECIPE}.PushForward"},
    "loss": {"_target_": f"{RECIPE}.LossTerms"},
    "compile": {"_target_": f"{RECIPE}.Compile"},
}
# Each flat lit key of an earlier run: its group and its name there.
LIT_KEYS = {
    "noise_std": ("noise", "std"),
    "noise_rest_scale": ("noise", "rest_scale"),
    "contact_noise_depth": ("noise", "contact_depth"),
    "contact_noise_prob": ("noise", "contact_prob"),
    "contact_touch": ("noise", "contact_touch"),
    "pushforward_steps": ("pushforward", "steps"),
    "pushforward_after": ("pushforward", "after"),
    "pushforward_growth": ("pushforward", "growth"),
    "lambda_energy": ("loss", "lambda_energy"),
    "lambda_contact": ("loss", "lambda_contact"),
    "contact_tol": ("loss", "contact_tol"),
    "lambda_rest": ("loss", "lambda_rest"),
    "truth_contacts": ("loss", "truth_contacts"),
    "compile": ("compile", "enabled"),
    "compile_mode": ("compile", "mode"),
    "compile_shapes": ("compile", "shapes"),
}
# Recipe keys that runs before the contact changes lack, with the value their recipe had (the
# loss's graph on the state's own motion: docs/TRAINING.md).
PREVIOUS_LIT = {"truth_contacts": False}
# Each grouped recipe key of today, with its flat name (lit.noise.std -> lit.noise_std).
FLAT_LIT_NAMES = {f"lit.{node}.{name}": f"lit.{key}" for key, (node, name) in LIT_KEYS.items()}
RUN_LENGTH_DECAY = "physgnn.training.schedule.RunLengthDecay"


def model_of_today(model: DictConfig) -> DictConfig:
    """``model`` (a run's ``model`` node) in today's layout: a moved target renamed; a model
    without a ``network`` node (an earlier physgnn's) with the keys it lacks at its own model's
    values (:data:`EARLIER_MODEL`); a learned simulator without the keys of the contact changes
    with its own model's values (:data:`PREVIOUS_MODEL`); then every flat key moved into its
    node (:data:`FLAT_KEYS`). A model of today's layout comes back as it is."""
    flat = OmegaConf.to_container(model, resolve=False)
    if flat.get("_target_") in MOVED_TARGETS:
        flat["_target_"] = MOVED_TARGETS[flat["_target_"]]
    if "network" not in flat:
        flat = EARLIER_MODEL | flat
    if flat.get("_target_") == LEARNED and "contacts" not in flat:
        flat = PREVIOUS_MODEL | flat
    nested = _into_nodes(flat, FLAT_KEYS, NODES)
    if nested.get("_target_") == LEARNED:  # runs before the engine state had the FD state
        for node, keys in BEFORE_ENGINE_STATE.items():
            group = nested.setdefault(node, dict(NODES[node]))
            group.update({k: v for k, v in keys.items() if k not in group})
    return OmegaConf.create(nested)


def _into_nodes(flat: dict, keys: dict, nodes: dict, every_node: bool = False) -> dict:
    """``flat`` with each of its flat ``keys`` (``{key: (node, name)}``) moved into its node,
    a node made from its Hydra keys (``nodes``) where first needed, or every one of them
    (``every_node``)."""
    nested = {k: v for k, v in flat.items() if k not in keys}
    if every_node:
        nested |= {node: dict(hydra) for node, hydra in nodes.items()}
    for key, (node, name) in keys.items():
        if key in flat:
            nested.setdefault(node, dict(nodes[node]))[name] = flat[key]
    return nested


def key_of_today(key: str) -> str:
    """``"model.M=1"`` → ``"model.network.M=1"``, ``"lit.noise_std=0"`` → ``"lit.noise.std=0"``:
    a dotted key (or ``key=value``) of the flat layout in today's; any other key comes back as
    it is."""
    if "=" not in key:
        return _name_of_today(key)
    given = parse_override(key)
    return f"{given.prefix}{_name_of_today(given.key)}={given.written}"


def _name_of_today(name: str) -> str:
    if name.startswith("model.") and name.count(".") == 1 and name[6:] in FLAT_KEYS:
        name = "model." + ".".join(FLAT_KEYS[name[6:]])
    return renamed_key(name) or name


def flat_layout(keys: dict) -> dict:
    """``{dotted key: value}`` of a composed config with its model and recipe keys in the flat
    layout (``model.network.M`` → ``model.M``, ``lit.noise.std`` → ``lit.noise_std``, the
    nodes' Hydra keys dropped, a run-length decay's ``decay_per_epoch`` and ``epochs`` as the
    ``final_lr_factor`` they make): the inverse of :func:`key_of_today`, so that what names a
    configuration does not change with its spelling."""
    before = {f"model.{node}.{name}": f"model.{key}" for key, (node, name) in FLAT_KEYS.items()}
    before |= FLAT_LIT_NAMES
    hydra = {f"model.{node}.{key}" for node, keys in NODES.items() for key in keys}
    hydra |= {f"lit.{node}.{key}" for node, keys in LIT_NODES.items() for key in keys}
    flat = {before.get(k, k): _flat_reference(v) for k, v in keys.items() if k not in hydra}
    if flat.get("lit.scheduler._target_") == RUN_LENGTH_DECAY:
        decay, epochs = flat.pop("lit.scheduler.decay_per_epoch"), flat.pop("lit.scheduler.epochs")
        flat["lit.scheduler.final_lr_factor"] = float(decay) ** int(epochs)
    return flat


def _flat_reference(value):
    """An interpolation of a recipe key in the flat layout (``${lit.pushforward.steps}`` →
    ``${lit.pushforward_steps}``); any other value as it is."""
    if isinstance(value, str) and value.startswith("${lit."):
        name = value[2:-1]
        return "${" + FLAT_LIT_NAMES.get(name, name) + "}"
    return value


def dotted_model(model: DictConfig) -> dict:
    """``{"H": 2, "network.M": 5, ...}``: a model config's keys, those of its nodes dotted."""
    out = {}
    for key, value in OmegaConf.to_container(model, resolve=True).items():
        if isinstance(value, dict):
            out |= {f"{key}.{k}": v for k, v in value.items()}
        else:
            out[key] = value
    return out


def lit_of_today(lit: DictConfig) -> DictConfig:
    """``lit`` (a run's ``lit`` node) in today's layout: flat recipe keys (an earlier physgnn's:
    no ``noise`` group) moved into their groups (:data:`LIT_KEYS`, the keys such a run lacks
    at its recipe's values: :data:`PREVIOUS_LIT`), and a run-length decay's
    ``final_lr_factor`` f written as ``decay_per_epoch: f, epochs: 1`` (the same factor). A
    ``lit`` of today's layout comes back as it is."""
    flat = OmegaConf.to_container(lit, resolve=False)
    if not isinstance(flat.get("noise"), dict):
        flat = _into_nodes(PREVIOUS_LIT | flat, LIT_KEYS, LIT_NODES, every_node=True)
    scheduler = flat.get("scheduler")
    if isinstance(scheduler, dict) and "final_lr_factor" in scheduler:
        factor = scheduler.pop("final_lr_factor")
        scheduler |= {"decay_per_epoch": factor, "epochs": 1}
    return OmegaConf.create(flat)


def renamed_key(name: str) -> str | None:
    """Today's spelling of a flat recipe key (``lit.noise_std`` → ``lit.noise.std``) or of a
    flat key of the simulator's groups (``model.contact_passes`` →
    ``model.contacts.contact_passes``), None for any other key."""
    if name.startswith("lit.") and name[4:] in LIT_KEYS:
        return "lit." + ".".join(LIT_KEYS[name[4:]])
    if name.startswith("model.") and FLAT_KEYS.get(name[6:], ("",))[0] in MODEL_GROUPS:
        return "model." + ".".join(FLAT_KEYS[name[6:]])
    return None


def check_renamed(argv: list[str]) -> None:
    """A flat recipe or simulator key of an earlier physgnn on a command line
    (``lit.noise_std=0.01``, ``model.contact_passes=0``, a ``final_lr_factor``) is refused in
    one line naming today's key."""
    for given in parse_overrides(argv):
        name, value = given.key, given.written
        new = renamed_key(name)
        if new:
            fix = new if given.prefix == "~" else f"{new}={value}"
            raise ConfigError(f"{name} is now {new}: write {fix}")
        if name == "lit.scheduler.final_lr_factor":
            raise ConfigError(
                f"{name} is now lit.scheduler.decay_per_epoch ** lit.scheduler.epochs: write "
                f"lit.scheduler.decay_per_epoch={value} lit.scheduler.epochs=1 for the same factor"
            )
