"""The range of each constructor argument of a training config whose constructor refuses
some values (:func:`physgnn.training.checks.check_arguments` checks every key against it).
The constructors (the network's, the data module's) are not option groups of their own, so
their ranges are declared here, by config key, as the groups declare theirs beside each field
(:mod:`physgnn.ranges`)."""

from __future__ import annotations

from physgnn.ranges import Allowed, whole

# The values a constructor argument takes, where it refuses others itself (in a message that
# names no key, wrapped by Hydra's "Error in call to target")
RANGES: dict[str, Allowed] = {
    "model.H": whole(0, what="velocities of history"),
    "model.network.M": whole(1, what="message-passing steps"),
    "model.network.hidden": whole(1, what="units per layer"),
    "model.network.num_materials": whole(0, what="materials; 0: none"),
    "model.network.material_dim": whole(0, what="material embedding size; 0: none"),
    "datamodule.batch_size": whole(1, what="pairs per step"),
    "datamodule.pairs_per_epoch": whole(1, what="training pairs per epoch"),
    "datamodule.val_pairs": whole(1, what="validation pairs"),
    "datamodule.num_workers": whole(0, what="loader processes; 0: none"),
}


def check_range(key: str, value) -> None:
    """``value`` of ``key`` lies in its :data:`RANGES` (``model.network.M=0``:
    ``model.network.M must be a whole number >= 1 (message-passing steps), got 0 (e.g.
    model.network.M=1)``); NaN never does. The option groups (``lit.noise`` ...,
    ``model.inputs``, ``model.contacts``) check their own ranges."""
    if key in RANGES and value is not None:
        RANGES[key].check(key, value)
