"""The training recipe of :class:`~physgnn.training.lit.LitSimulator` in four groups, each a
frozen dataclass: the one source of its defaults, units and ranges. Each is mirrored by one
node of ``conf/lit/default.yaml`` (``lit.noise``, ``lit.pushforward``, ``lit.loss``,
``lit.compile``: its keys are the fields, Hydra builds it from its ``_target_``); a value out
of range is refused when the group is made, in one line naming the key and its default
(:func:`physgnn.ranges.check_fields`: a field's range is its metadata). Lengths are in mean
sphere diameters d (the simulator's ``length_scale``), noise in normalised units, steps in
optimiser steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from physgnn.ranges import FLAG, check_fields, number, one_of, ranged, whole

# torch.compile's modes (checked whether or not compiling is on, so that a run does not fail
# the day it is switched on)
COMPILE_MODES = ("default", "reduce-overhead", "max-autotune", "max-autotune-no-cudagraphs")
DIAMETERS = number(0, what="sphere diameters")
WEIGHT = number(0, what="a loss weight; 0: off")
STEPS = whole(0, what="optimiser steps; 0: off")


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
    std: float = ranged(number(0, what="normalised units; 0: no noise"), default=0.03)
    rest_scale: float = ranged(
        number(0, 1, above=True, what="a factor; 1: full noise at rest"), default=0.05
    )
    contact_depth: float = ranged(DIAMETERS, default=0.2)
    contact_prob: float = ranged(
        number(0, 1, what="a probability; 0: no contact noise"), default=0.3
    )
    contact_touch: float = ranged(DIAMETERS, default=0.05)

    def __post_init__(self) -> None:
        check_fields(self)

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
    steps: int = ranged(STEPS, default=2)
    after: int = ranged(STEPS, default=400)
    growth: int = ranged(STEPS, default=0)

    def __post_init__(self) -> None:
        check_fields(self)


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
    lambda_energy: float = ranged(WEIGHT, default=0.0)
    lambda_contact: float = ranged(WEIGHT, default=1.0)
    contact_tol: float = ranged(DIAMETERS, default=0.02)
    lambda_rest: float = ranged(WEIGHT, default=1.0)
    truth_contacts: bool = ranged(FLAG, default=True)
    event_share: float = ranged(number(0, 1, below=True, what="a share"), default=0.0)
    event_speed: float = ranged(number(0, what="m/s"), default=0.05)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class Compile:
    """``enabled``: torch.compile the regions of
    :meth:`~physgnn.training.lit.LitSimulator.compile_regions` in ``mode``, at most ``shapes``
    input shapes (a new one past them runs eager with a warning: :mod:`physgnn.models.capture`)."""

    NODE: ClassVar[str] = "lit.compile"
    enabled: bool = ranged(FLAG, default=False)
    mode: str = ranged(one_of(*COMPILE_MODES), default="default")
    shapes: int = ranged(whole(1, what="input shapes to compile"), default=16)

    def __post_init__(self) -> None:
        check_fields(self)
