"""The range of each constructor argument of a training config whose constructor refuses
some values (:func:`physgnn.training.checks.check_arguments` checks every key against it)."""

from __future__ import annotations

from physgnn.errors import ConfigError

# The values a constructor argument takes, where it refuses others itself (in a message that
# names no key, wrapped by Hydra's "Error in call to target"): key -> (least, whether the least
# itself is allowed, most or None, what it is).
RANGES = {
    "model.H": (0, True, None, "velocities of history"),
    "model.network.M": (1, True, None, "message-passing steps"),
    "model.network.hidden": (1, True, None, "units per layer"),
    "model.network.num_materials": (0, True, None, "materials; 0: none"),
    "model.network.material_dim": (0, True, None, "material embedding size; 0: none"),
    "datamodule.batch_size": (1, True, None, "pairs per step"),
    "datamodule.pairs_per_epoch": (1, True, None, "training pairs per epoch"),
    "datamodule.val_pairs": (1, True, None, "validation pairs"),
    "datamodule.num_workers": (0, True, None, "loader processes; 0: none"),
}


def check_range(key: str, value, hint=None) -> None:
    """``value`` of ``key`` lies in its :data:`RANGES` (``model.network.M=0``:
    ``model.network.M must be a whole number >= 1 (message-passing steps), got 0``); NaN never
    does. The recipe's groups (``lit.noise`` ...) and the model's (``model.inputs``,
    ``model.contacts``) check their own ranges (:mod:`physgnn.training.recipe`,
    :mod:`physgnn.models.options`)."""
    if key not in RANGES or not isinstance(value, int | float) or isinstance(value, bool):
        return
    least, closed, most, what = RANGES[key]
    above = value >= least if closed else value > least
    if not (above and (most is None or value <= most)):
        kind = "a whole number" if hint is int else "a number"
        bound = f"{'>=' if closed else '>'} {least}" + (f" and <= {most}" if most else "")
        raise ConfigError(f"{key} must be {kind} {bound} ({what}), got {value!r}")
