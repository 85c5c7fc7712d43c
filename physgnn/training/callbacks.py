"""Lightning callback: rollouts on a few validation trajectories and the OOD scenes.

Every ``every_n_epochs`` validation epochs it rolls out, with the module's simulator
(``pl_module.simulator``), the first ``n_val_trajectories`` of ``<data_dir>/val.h5`` and every
scene of ``<data_dir>/ood.h5`` (``data_dir`` is the datamodule's), each cut to ``max_frames``,
and logs through ``pl_module.log`` so every logger receives:
``val/rollout_mse``, ``val/chamfer``, ``ood/mse``, ``ood/chamfer``, ``ood/energy_gain``,
``ood/depth_sphere``, ``ood/pct_sphere``, ``ood/diverged`` (fraction of rollouts) and
``rollout/fps``. Means are over trajectories; a diverged rollout counts on its finite prefix.

``val/rollout_score`` is what checkpoints are chosen on (``conf/callbacks/default.yaml``):
the mean position MSE of the validation rollouts, or infinity when any of them diverged (a
diverged rollout's prefix must not look good). Validation data only: test and OOD scenes
never choose anything. Between two rollout epochs the score of the latest one is logged
again, so a checkpoint callback monitoring it finds it at every validation.
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch

from physgnn import metrics
from physgnn.data.dataset import read_split
from physgnn.rollout import rollout

VAL_KEYS = {"mse": "val/rollout_mse", "chamfer": "val/chamfer"}
OOD_KEYS = {k: f"ood/{k}" for k in ("mse", "chamfer", "energy_gain", "depth_sphere", "pct_sphere")}


class RolloutCallback(L.Callback):
    def __init__(
        self,
        every_n_epochs: int = 5,
        n_val_trajectories: int = 2,
        max_frames: int | None = 100,
        ood: bool = True,
    ):
        if every_n_epochs < 1 or n_val_trajectories < 0:
            raise ValueError("every_n_epochs must be >= 1 and n_val_trajectories >= 0")
        self.every_n_epochs = int(every_n_epochs)
        self.n_val_trajectories = int(n_val_trajectories)
        self.max_frames = None if max_frames is None else int(max_frames)
        self.ood = bool(ood)
        self._cache: dict[str, list] = {}
        self._score: float | None = None

    def _trajectories(self, data_dir: Path, split: str) -> list:
        """Trajectories of a split, cut to ``max_frames`` (read once, then cached)."""
        if split not in self._cache:
            path = data_dir / f"{split}.h5"
            trajs = read_split(path) if path.exists() else []
            if split == "val":
                trajs = trajs[: self.n_val_trajectories]
            self._cache[split] = [t.truncated(self.max_frames) for t in trajs]
        return self._cache[split]

    def rollout_metrics(self, simulator, trajectories: list) -> tuple[list[dict], list[float]]:
        """Metrics and FPS of each trajectory's rollout (eval mode restored afterwards)."""
        was_training = simulator.training
        simulator.eval()
        try:
            rows, fps = [], []
            for traj in trajectories:
                (pred,) = rollout(simulator, [traj])
                rows.append(metrics.trajectory_metrics(pred, traj))
                if pred.fps is not None:
                    fps.append(float(pred.fps))
        finally:
            simulator.train(was_training)
        return rows, fps

    def on_validation_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if trainer.sanity_checking:
            return
        due = (trainer.current_epoch + 1) % self.every_n_epochs == 0
        if due or self._score is None:
            self.log_rollouts(pl_module, Path(trainer.datamodule.data_dir))
        elif self._score is not None:
            pl_module.log("val/rollout_score", self._score, on_step=False, on_epoch=True)

    def state_dict(self) -> dict:
        return {"score": self._score}

    def load_state_dict(self, state_dict: dict) -> None:
        self._score = state_dict.get("score")

    def log_rollouts(self, pl_module: L.LightningModule, data_dir: Path) -> dict[str, float]:
        """Roll out, log with ``pl_module.log`` and return what was logged."""
        values: dict[str, float] = {}
        all_fps: list[float] = []
        groups = [("val", VAL_KEYS)] + ([("ood", OOD_KEYS)] if self.ood else [])
        with torch.inference_mode():
            for split, keys in groups:
                trajs = self._trajectories(data_dir, split)
                if not trajs:
                    continue
                rows, fps = self.rollout_metrics(pl_module.simulator, trajs)
                all_fps += fps
                for key, name in keys.items():
                    vals = [r[key] for r in rows if r[key] is not None]
                    if vals:
                        values[name] = float(np.mean(vals))
                if split == "val":
                    diverged = any(r["diverged_at"] is not None for r in rows)
                    self._score = (
                        float("inf") if diverged else float(np.mean([r["mse"] for r in rows]))
                    )
                    values["val/rollout_score"] = self._score
                if split == "ood":
                    values["ood/diverged"] = float(
                        np.mean([r["diverged_at"] is not None for r in rows])
                    )
        if all_fps:
            values["rollout/fps"] = float(np.mean(all_fps))
        for name, value in values.items():
            pl_module.log(name, value, on_step=False, on_epoch=True, sync_dist=False)
        return values
