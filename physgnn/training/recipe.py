"""The training recipe of :class:`~physgnn.training.lit.LitSimulator` in four groups, each a
frozen dataclass: the one source of its defaults, units and ranges. Each is mirrored by one
node of ``conf/lit/default.yaml`` (``lit.noise``, ``lit.pushforward``, ``lit.loss``,
``lit.compile``: its keys are the fields, Hydra builds it from its ``_target_``); a value out
of range is refused when the group is made, in one line naming the key
(:class:`~physgnn.errors.ConfigError`). Lengths are in mean sphere diameters d (the
simulator's ``length_scale``), noise in normalised units, steps in optimiser steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

from physgnn.errors import ConfigError

# torch.compile's modes (checked whether or not compiling is on, so that a run does not fail
# the day it is switched on)
COMPILE_MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")


def _refuse(group, key: str, rule: str) -> None:
    """One line naming the key, its rule, the value given and the default."""
    default = next(f.default for f in fields(group) if f.name == key)
    value = getattr(group, key)
    raise ConfigError(
        f"{group.NODE}.{key} must be {rule}, got {value!r} (the default: "
        f"{group.NODE}.{key}={default})"
    )


def _number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _check_at_least(group, keys: tuple[str, ...], least: float, what: str) -> None:
    """Every field of ``keys`` a finite number >= ``least``."""
    for key in keys:
        value = getattr(group, key)
        if not _number(value) or value < least:
            _refuse(group, key, f"a number >= {least} ({what})")


def _check_whole(group, keys: tuple[str, ...], least: int, what: str) -> None:
    """Every field of ``keys`` a whole number >= ``least``."""
    for key in keys:
        value = getattr(group, key)
        if not isinstance(value, int) or isinstance(value, bool) or value < least:
            _refuse(group, key, f"a whole number >= {least} ({what})")


@dataclass(frozen=True)
class InputNoise:
    """Noise added to each training batch (:mod:`physgnn.training.noise`,
    :mod:`physgnn.training.contacts`).

    ``std``: the random walk along each velocity history, σ in normalised units (0: none);
    ``rest_scale``: a resting sphere's share of it, the factor clamp(speed / σ_v,
    ``rest_scale``, 1) (1: every sphere the full noise); ``contact_depth`` (d): each contact
    closer than ``contact_touch`` (d) is pushed in by up to it, with probability
    ``contact_prob`` (0 for either: no contact noise)."""

    NODE: ClassVar[str] = "lit.noise"
    std: float = 0.03
    rest_scale: float = 0.05
    contact_depth: float = 0.2
    contact_prob: float = 0.3
    contact_touch: float = 0.05

    def __post_init__(self) -> None:
        _check_at_least(self, ("std",), 0, "normalised units; 0: no noise")
        _check_at_least(self, ("contact_depth", "contact_touch"), 0, "sphere diameters")
        if not _number(self.rest_scale) or not 0 < self.rest_scale <= 1:
            _refuse(self, "rest_scale", "a factor in (0, 1] (1: full noise at rest)")
        if not _number(self.contact_prob) or not 0 <= self.contact_prob <= 1:
            _refuse(self, "contact_prob", "a probability in [0, 1] (0: no contact noise)")

    @property
    def contacts(self) -> bool:
        """Whether contacts are pushed in at all."""
        return self.contact_depth > 0 and self.contact_prob > 0


@dataclass(frozen=True)
class PushForward:
    """Each batch first rolls the model itself ``k ~ U{0..steps}`` steps (no gradients) from
    optimiser step ``after`` on (``steps`` = 0: one-step training); ``growth`` = G > 0: the
    longest unroll is 1 from ``after``, then one more every G steps up to ``steps``."""

    NODE: ClassVar[str] = "lit.pushforward"
    steps: int = 2
    after: int = 400
    growth: int = 0

    def __post_init__(self) -> None:
        _check_whole(self, ("steps", "after", "growth"), 0, "optimiser steps; 0: off")


@dataclass(frozen=True)
class LossTerms:
    """The weights of the loss's terms besides the MSE (0 turns one off): ``lambda_energy``
    (energy increase per Σmg), ``lambda_contact`` (the hinge on overlaps deeper than
    ``contact_tol``, d), ``lambda_rest`` (the rest decision's cross-entropy);
    ``truth_contacts``: the loss's graph is also built on the target velocities, so every
    contact of the truth has its edges and its spheres in the loss; ``event_share``: the share
    of the regression loss's weight at least given to moving contacts (spheres whose truth
    departs from ballistic flight by more than ``event_speed`` m/s and does not come to rest:
    1.2 % of the training sphere-frames; 0: every sphere the same weight,
    :func:`~physgnn.training.losses.regime_weights`)."""

    NODE: ClassVar[str] = "lit.loss"
    lambda_energy: float = 0.0
    lambda_contact: float = 1.0
    contact_tol: float = 0.02
    lambda_rest: float = 1.0
    truth_contacts: bool = True
    event_share: float = 0.0
    event_speed: float = 0.05

    def __post_init__(self) -> None:
        weights = ("lambda_energy", "lambda_contact", "lambda_rest")
        _check_at_least(self, weights, 0, "a loss weight; 0: off")
        _check_at_least(self, ("contact_tol",), 0, "sphere diameters")
        _check_at_least(self, ("event_speed",), 0, "m/s")
        if not 0 <= self.event_share < 1:
            _refuse(self, "event_share", "a share in [0, 1)")
        if not isinstance(self.truth_contacts, bool):
            _refuse(self, "truth_contacts", "true or false")


@dataclass(frozen=True)
class Compile:
    """``enabled``: torch.compile the regions of
    :meth:`~physgnn.training.lit.LitSimulator.compile_regions` in ``mode``, at most ``shapes``
    input shapes (a new one past them runs eager with a warning: :mod:`physgnn.models.capture`)."""

    NODE: ClassVar[str] = "lit.compile"
    enabled: bool = False
    mode: str = "default"
    shapes: int = 16

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            _refuse(self, "enabled", "true or false")
        if self.mode not in COMPILE_MODES:
            _refuse(self, "mode", f"one of {', '.join(COMPILE_MODES)}")
        _check_whole(self, ("shapes",), 1, "input shapes to compile")
