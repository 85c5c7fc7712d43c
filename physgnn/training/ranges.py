"""The range of each constructor argument of a training config whose constructor refuses
some values (:func:`physgnn.training.checks.check_arguments` checks every key against it).
The constructors (the network's, the graph builder's, the data module's, the rollout
callback's, Lightning's trainer) are not option groups of their own, so their ranges are
declared here, by config key, as the groups declare theirs beside each field
(:mod:`physgnn.ranges`)."""

from __future__ import annotations

from physgnn.ranges import Allowed, number, one_of, whole

# The graph builder's choices (physgnn.graph.rules.CONNECTIVITIES, physgnn.graph.neighbors.
# BACKENDS: the graph is below what training imports; tests/test_train_mistakes.py compares)
CONNECTIVITIES = ("approach", "epsilon", "vmax", "vi")
BACKENDS = ("auto", "torch", "kdtree", "cluster")

# The values a constructor argument takes, where it refuses others itself (in a message that
# names no key, wrapped by Hydra's "Error in call to target") or takes them silently
RANGES: dict[str, Allowed] = {
    "model.H": whole(0, what="velocities of history"),
    "model.network.M": whole(1, what="message-passing steps"),
    "model.network.hidden": whole(1, what="units per layer"),
    "model.network.num_materials": whole(0, what="materials; 0: none"),
    "model.network.material_dim": whole(0, what="material embedding size; 0: none"),
    "model.graph.connectivity": one_of(*CONNECTIVITIES, what="the rules that link pairs"),
    "model.graph.backend": one_of(*BACKENDS, what="the neighbour search"),
    "model.graph.epsilon": number(0, what="m"),
    "model.graph.factor": number(0, what="scales the velocity terms"),
    "model.graph.clip_margin": number(0, what="m"),
    "datamodule.batch_size": whole(1, what="pairs per step"),
    "datamodule.pairs_per_epoch": whole(1, what="training pairs per epoch"),
    "datamodule.val_pairs": whole(1, what="validation pairs"),
    "datamodule.num_workers": whole(0, what="loader processes; 0: none"),
    "callbacks.rollout.every_n_epochs": whole(1, what="validation epochs between rollouts"),
    "callbacks.rollout.w_depth": number(0, what="the score's weight of depth"),
    "callbacks.rollout.w_tunnel": number(0, what="the score's weight of tunnelling"),
    "callbacks.rollout.w_rest": number(0, what="the score's weight of rest drift"),
    # Lightning turns clipping off for a negative value, without a word
    "trainer.gradient_clip_val": number(
        0, also=(None,), what="the gradients' largest norm; 0 or null: no clipping", example=1.0
    ),
}


def check_range(key: str, value) -> None:
    """``value`` of ``key`` lies in its :data:`RANGES` (``model.network.M=0``:
    ``model.network.M must be a whole number >= 1 (message-passing steps), got 0 (e.g.
    model.network.M=1)``); NaN never does; a choice misspelt is answered with the closest
    (``did you mean model.graph.connectivity=epsilon?``). The option groups (``lit.noise``
    ..., ``model.inputs``, ``model.contacts``) check their own ranges."""
    if key in RANGES and value is not None:
        RANGES[key].check(key, value)
