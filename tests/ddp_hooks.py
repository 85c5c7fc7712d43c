"""``python tests/ddp_hooks.py [overrides]``: ``python -m physgnn.train`` with two test hooks,
installed in every DDP process (Lightning starts the others with this same command line):

- ``PHYSGNN_PROBE=DIR``: process r keeps ``DIR/rank<r>.json`` up to date: the noise seed
  and push-forward length of each training step, the trajectories it rolled out and the
  rollout score of each validation, and the best checkpoint so far.
- ``PHYSGNN_NAN_AT=R:S``: the training loss of process R is NaN at global step S.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's physgnn

import lightning as L  # noqa: E402

from physgnn import train as train_command  # noqa: E402
from physgnn.training import build as build_module  # noqa: E402
from physgnn.training.callbacks import RolloutCallback  # noqa: E402
from physgnn.training.lit import LitSimulator  # noqa: E402


class Probe(L.Callback):
    """What each process drew and logged so far (``PHYSGNN_PROBE``), written at every hook."""

    rolled: list[int] = []  # trajectories of each call of RolloutCallback.rollout_metrics

    def __init__(self, folder: str):
        self.folder = Path(folder)
        self.steps: list[list[int]] = []
        self.scores: list[float] = []

    def dump(self, trainer) -> None:
        ckpt = trainer.checkpoint_callback
        best = None if ckpt.best_model_score is None else float(ckpt.best_model_score)
        out = {
            "steps": self.steps,
            "scores": self.scores,
            "rolled": self.rolled,
            "best": ckpt.best_model_path,
            "best_score": best,
        }
        (self.folder / f"rank{trainer.global_rank}.json").write_text(json.dumps(out))

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        seed = pl_module._noise_generator().initial_seed()
        self.steps.append([pl_module.global_step, seed, pl_module._unroll_length()])
        self.dump(trainer)

    def on_validation_end(self, trainer, pl_module) -> None:
        self.scores.append(float(trainer.callback_metrics["val/rollout_score"]))
        self.dump(trainer)


def install() -> None:
    if folder := os.environ.get("PHYSGNN_PROBE"):
        build_trainer, rollout_metrics = build_module.build_trainer, RolloutCallback.rollout_metrics

        def probed(cfg, extra=()):
            return build_trainer(cfg, [*extra, Probe(folder)])

        def counted(self, simulator, trajectories):
            Probe.rolled.append(len(trajectories))
            return rollout_metrics(self, simulator, trajectories)

        build_module.build_trainer, RolloutCallback.rollout_metrics = probed, counted
    if at := os.environ.get("PHYSGNN_NAN_AT"):
        rank, step = (int(x) for x in at.split(":"))
        losses = LitSimulator.losses

        def poisoned(self, state):
            out = losses(self, state)
            if self.training and (self.global_rank, self.global_step) == (rank, step):
                out["loss"] = out["loss"] * float("nan")
            return out

        LitSimulator.losses = poisoned


if __name__ == "__main__":
    install()
    train_command.main()
