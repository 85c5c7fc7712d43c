"""The numerics fingerprint: the first training losses of one seed and a rollout's positions,
on the tiny preset with one thread, against the values pinned in ``tests/fingerprint.json``.

A change to the training's numerics (inputs, graph, network, noise, loss, optimiser, data
order) changes them and fails here, loudly: the README's and docs/results' figures were
measured before it and must be measured again (``make study`` into a new registry, then
``make default-table``). When the change is meant, re-pin in one command::

    make fingerprint        # PHYSGNN_REPIN=1: rewrites tests/fingerprint.json

The config is spelled out key by key (:data:`CONFIG`), not taken from the defaults, so that a
change of the *default* model or recipe (conf/) does not move the fingerprint; a change of
the code's numerics does. A new model or training key that changes numerics by default fails
here too: add it to :data:`CONFIG` with its old value, or re-pin.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import lightning as L
import numpy as np
import torch
from trainkit import config

from physgnn.data.dataset import read_split
from physgnn.rollout import rollout
from physgnn.training.build import build

PINNED = Path(__file__).with_name("fingerprint.json")
CONFIG = [
    "seed=0",
    # the model, every key that shapes its numerics
    "model.H=2",
    "model.network.M=1",
    "model.network.hidden=16",
    "model.graph.connectivity=vi",
    "model.graph.epsilon=0.01",
    "model.graph.factor=1.0",
    "model.network.third_law=true",
    "model.network.use_surfaces=true",
    "model.inputs.boundary_features=false",
    "model.inputs.contact_features=true",
    "model.inputs.material_features=true",
    "model.contacts.gravity_prior=true",
    "model.network.layer_norm=false",
    "model.graph.clip_margin=1.0",
    # the invariance keys (default since), at the values the fingerprint was measured with
    "model.inputs.relative_pairs=false",
    "model.inputs.mass_ratio=false",
    "model.network.aggregation=sum",
    "model.contacts.rest_decision=false",
    "model.contacts.rest_speed=0.01",
    # the engine state and what it came with (default since), off as when pinned
    "model.inputs.engine_state=false",
    "model.contacts.plane_floor=false",
    "lit.loss.event_share=0.0",
    # the rollout guards (default since; rollouts only): off as when pinned
    "model.contacts.energy_guard=false",
    "model.contacts.friction_cone=false",
    "model.contacts.rest_consistent=false",
    # the recipe: noise, push-forward (from step 2 of 4), contact terms, Adam, schedule
    "lit.noise.std=0.03",
    "lit.pushforward.steps=2",
    "lit.pushforward.after=2",
    "lit.pushforward.growth=0",
    "lit.loss.lambda_energy=0.0",
    "lit.loss.lambda_contact=1.0",
    "lit.loss.contact_tol=0.02",
    "lit.noise.contact_depth=0.2",
    "lit.noise.contact_prob=0.3",
    "lit.noise.contact_touch=0.05",
    "lit.noise.rest_scale=1.0",
    "lit.loss.lambda_rest=0.0",
    "lit.optimizer.lr=1.0e-3",
    "lit.scheduler.decay_per_epoch=0.97",
    "lit.scheduler.epochs=90",
    # 4 steps of 4 pairs, no callbacks, no logger
    "datamodule.batch_size=4",
    "datamodule.pairs_per_epoch=16",
    "datamodule.val_pairs=8",
    "trainer.max_epochs=1",
    "trainer.max_time=null",
    "trainer.enable_progress_bar=false",
    "trainer.enable_model_summary=false",
    "+trainer.enable_checkpointing=false",
    "callbacks=none",
    "~logger",
]
ROLLOUT_FRAMES = 8
RTOL, ATOL = 1e-4, 1e-5


class LossRecorder(L.Callback):
    def __init__(self):
        self.losses: list[float] = []

    def on_train_batch_end(self, trainer, module, outputs, batch, batch_idx) -> None:
        loss = outputs["loss"] if isinstance(outputs, dict) else outputs
        self.losses.append(float(loss))


def measure(tiny_dataset, run_dir) -> dict:
    """The losses of the first steps and the last rollout frame's positions (1 thread)."""
    cfg = config(tiny_dataset, run_dir, *CONFIG)
    L.seed_everything(cfg.seed, workers=True)
    recorder = LossRecorder()
    datamodule, lit, trainer = build(cfg, [recorder])
    trainer.fit(lit, datamodule=datamodule)
    truth = read_split(Path(tiny_dataset) / "test.h5")[0].truncated(ROLLOUT_FRAMES)
    lit.simulator.eval()
    with torch.no_grad():
        pred = rollout(lit.simulator, [truth])[0]
    last = pred.pos[-1].tolist()
    return {
        "train_losses": recorder.losses,
        "rollout_trajectory": truth.name,
        "rollout_frames": ROLLOUT_FRAMES,
        "rollout_last_pos": last,
    }


def repin(found: dict) -> None:
    rev = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    about = (
        "Numerics fingerprint of tests/test_fingerprint.py (tiny preset, 1 thread); "
        "re-pinned by `make fingerprint` when training numerics change on purpose."
    )
    pinned = {
        "about": about,
        "pinned_at": rev or None,
        "torch": torch.__version__,
        "config": CONFIG,
        **found,
    }
    PINNED.write_text(json.dumps(pinned, indent=1) + "\n")


def test_training_numerics_match_the_pinned_fingerprint(tiny_dataset, tmp_path, one_thread):
    found = measure(tiny_dataset, tmp_path)
    if os.environ.get("PHYSGNN_REPIN") == "1":
        repin(found)
    assert PINNED.is_file(), f"no {PINNED.name}: pin it with `make fingerprint`"
    pinned = json.loads(PINNED.read_text())
    how = (
        f"training numerics changed since {pinned.get('pinned_at')}: re-measure the README's "
        "figures, then re-pin with `make fingerprint` if the change is meant"
    )
    assert pinned["config"] == CONFIG, f"CONFIG differs from the pinned one; {how}"
    assert len(found["train_losses"]) == len(pinned["train_losses"]), how
    np.testing.assert_allclose(
        found["train_losses"], pinned["train_losses"], rtol=RTOL, err_msg=how
    )
    assert found["rollout_trajectory"] == pinned["rollout_trajectory"], how
    np.testing.assert_allclose(
        found["rollout_last_pos"], pinned["rollout_last_pos"], rtol=RTOL, atol=ATOL, err_msg=how
    )
