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
    "model.boundary_radius": (0, False, None, "m"),
    "model.rest_speed": (0, False, None, "m/s"),
    "datamodule.batch_size": (1, True, None, "pairs per step"),
    "datamodule.pairs_per_epoch": (1, True, None, "training pairs per epoch"),
    "datamodule.val_pairs": (1, True, None, "validation pairs"),
    "datamodule.num_workers": (0, True, None, "loader processes; 0: none"),
    "lit.noise_std": (0, True, None, "input noise, normalised units; 0: none"),
    "lit.lambda_energy": (0, True, None, "a loss weight; 0: off"),
    "lit.lambda_contact": (0, True, None, "a loss weight; 0: off"),
    "lit.lambda_rest": (0, True, None, "a loss weight; 0: off"),
    "lit.pushforward_steps": (0, True, None, "steps; 0: off"),
    "lit.pushforward_after": (0, True, None, "steps"),
    "lit.pushforward_growth": (0, True, None, "steps; 0: off"),
    "lit.contact_tol": (0, True, None, "sphere diameters"),
    "lit.contact_noise_depth": (0, True, None, "sphere diameters"),
    "lit.contact_touch": (0, True, None, "sphere diameters"),
    "lit.contact_noise_prob": (0, True, 1, "a probability; 0: off"),
    "lit.noise_rest_scale": (0, False, 1, "a factor; 1: full noise at rest"),
    "lit.compile_shapes": (1, True, None, "input shapes to compile"),
}
# The words a string argument takes (torch.compile's modes): checked whether or not it is used
# now (lit.compile=false), so that a run does not fail the day it is switched on.
CHOICES = {
    "lit.compile_mode": (
        "default",
        "reduce-overhead",
        "max-autotune",
        "max-autotune-no-cudagraphs",
    ),
}


def check_range(key: str, value, hint=None) -> None:
    """``value`` of ``key`` lies in its :data:`RANGES` (``model.network.M=0``:
    ``model.network.M must be a whole number >= 1 (message-passing steps), got 0``); NaN never
    does. A key of :data:`CHOICES` takes one of its words."""
    if key in CHOICES and value not in CHOICES[key]:
        raise ConfigError(f"{key} must be one of {', '.join(CHOICES[key])}, got {value!r}")
    if key not in RANGES or not isinstance(value, int | float) or isinstance(value, bool):
        return
    least, closed, most, what = RANGES[key]
    above = value >= least if closed else value > least
    if not (above and (most is None or value <= most)):
        kind = "a whole number" if hint is int else "a number"
        bound = f"{'>=' if closed else '>'} {least}" + (f" and <= {most}" if most else "")
        raise ConfigError(f"{key} must be {kind} {bound} ({what}), got {value!r}")
