"""Lightning callback: rollouts on a few validation trajectories and the OOD scenes.

Every ``every_n_epochs`` validation epochs it rolls out, with the module's simulator
(``pl_module.simulator``), the first ``n_val_trajectories`` of ``<data_dir>/val.h5`` up to
frame ``H + horizon`` (what the score needs: ``H + horizon + 1`` frames, seed frames included)
and, with ``ood``, every scene of ``<data_dir>/ood.h5`` cut to ``max_frames`` (``data_dir`` is
the datamodule's), and logs through ``pl_module.log`` so every logger receives:
``val/mse<horizon>`` (``val/mse20`` by default), ``val/rollout_mse``, ``val/chamfer``,
``val/energy_gain``, ``ood/mse``, ``ood/chamfer``, ``ood/energy_gain``, ``ood/depth_sphere``,
``ood/pct_sphere``, ``ood/diverged`` (fraction of rollouts) and ``rollout/fps``. Means are
over trajectories; a diverged rollout counts on its finite prefix. Every ``val/`` value is of
the validation rollouts as rolled out, frames 0 to ``H + horizon``: ``val/rollout_mse`` is the
position MSE over those frames, not over whole trajectories.

``val/rollout_score`` is what checkpoints are chosen on (``conf/callbacks/default.yaml``):
position error and physics together, the mean over the validation rollouts of

``MSE20 / d² + w_depth · (max sphere–sphere + max sphere–plane depth) + w_tunnel · tunnelled / N
+ w_rest · rest drift``

with MSE20 the position MSE at frame ``H + horizon``, the eval's ``mse20`` at ``horizon`` 20
(:func:`~physgnn.metrics.trajectory_metrics`, key ``mse<horizon>``), and the physics terms over
the same frames (d the mean sphere diameter of the validation trajectories; depths as
fractions of d, the deepest of the rollout, ground and other planes together;
``tunnelled / N`` the share of spheres whose centre crossed a plane; rest drift in radii of
the spheres the truth keeps at rest, counted where a trajectory has some), or infinity when
any rollout diverged before the horizon (a diverged rollout's prefix must not look good).
Position error alone rewards soft contacts (a model that lets spheres sink scores well on it).
The whole-rollout MSE is not in the score: past the first collisions it is chaos, not skill (a
1e-6 m nudge of the start moves the test MSE across 34.6–35.7 m², MSE20 by at most 0.007), and
so are the physics terms of whole rollouts (one ``small`` checkpoint over four such nudges:
max depth 0.452–0.483 d and tunnelled share 0–0.006 over whole rollouts, 0.4465 d and 0 at
every nudge up to the horizon; docs/TRAINING.md). The terms are logged too: ``val/max_depth``,
``val/tunnelled``, ``val/rest_drift``. Validation data only: test and OOD scenes never choose
anything. Between two rollout epochs the score of the latest one is logged again, so a
checkpoint callback monitoring it finds it at every validation.

A validation trajectory shorter than ``H + horizon + 1`` frames is refused in one line naming
``callbacks.rollout.horizon`` (the data preset's ``val_rollout.horizon``).

Under DDP the processes share the rollouts out (process r rolls out every r-th trajectory)
and gather every row, so each process logs the same values, computed from the rows in file
order, and the checkpoint callbacks of all processes choose the same checkpoint.
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
import torch.distributed as dist

from physgnn import metrics
from physgnn.data.dataset import read_split
from physgnn.errors import ConfigError
from physgnn.metrics import max_penetration
from physgnn.models.protocol import hooks_of
from physgnn.rollout import rollout

VAL_KEYS = {"mse": "val/rollout_mse", "chamfer": "val/chamfer", "energy_gain": "val/energy_gain"}
OOD_KEYS = {k: f"ood/{k}" for k in ("mse", "chamfer", "energy_gain", "depth_sphere", "pct_sphere")}


class RolloutCallback(L.Callback):
    def __init__(
        self,
        every_n_epochs: int = 10,
        n_val_trajectories: int = 10,
        max_frames: int | None = None,
        horizon: int = 20,
        ood: bool = False,
        w_depth: float = 10.0,
        w_tunnel: float = 10.0,
        w_rest: float = 1.0,
    ):
        if every_n_epochs < 1 or n_val_trajectories < 0 or horizon < 1:
            raise ValueError("every_n_epochs and horizon must be >= 1 and n_val_trajectories >= 0")
        if min(w_depth, w_tunnel, w_rest) < 0:
            raise ValueError("the score weights w_depth, w_tunnel, w_rest must be >= 0")
        self.weights = (float(w_depth), float(w_tunnel), float(w_rest))
        self.every_n_epochs = int(every_n_epochs)
        self.n_val_trajectories = int(n_val_trajectories)
        self.max_frames = None if max_frames is None else int(max_frames)
        self.horizon = int(horizon)
        self.ood = bool(ood)
        self._cache: dict[str, list] = {}
        self._score: float | None = None

    def _trajectories(self, data_dir: Path, split: str) -> list:
        """Trajectories of a split (read once, then cached): the first ``n_val_trajectories``
        of val, every OOD scene cut to ``max_frames``."""
        if split not in self._cache:
            path = data_dir / f"{split}.h5"
            trajs = read_split(path) if path.exists() else []
            if split == "val":
                self._cache[split] = trajs[: self.n_val_trajectories]
            else:
                self._cache[split] = [t.truncated(self.max_frames) for t in trajs]
        return self._cache[split]

    def to_horizon(self, trajectories: list, history: int) -> list:
        """The validation ``trajectories`` cut to frame ``history + horizon``, the last the score
        needs; one too short for it is refused (one line naming the key)."""
        frames = history + self.horizon + 1
        for t in trajectories:
            if t.n_frames < frames:
                raise ConfigError(
                    f"validation trajectory {t.name!r} has {t.n_frames} frames, the score needs "
                    f"H + horizon + 1 = {frames}: lower callbacks.rollout.horizon="
                    f"{self.horizon} (the data preset's val_rollout.horizon)"
                )
        return [t.truncated(frames) for t in trajectories]

    def rollout_metrics(self, simulator, trajectories: list) -> tuple[list[dict], list[float]]:
        """Metrics and FPS of each trajectory's rollout (eval mode restored afterwards). All the
        scenes roll out together, batched in one graph per frame (one rollout call): that
        differs from one-by-one rollouts only by float rounding, and is deterministic."""
        was_training = simulator.training
        simulator.eval()
        try:
            rows, fps = [], []
            for traj, pred in zip(trajectories, rollout(simulator, trajectories), strict=True):
                # energy from finite differences, as make eval measures every row's
                scored = pred.with_finite_velocities()
                row = metrics.trajectory_metrics(scored, traj, horizon=self.horizon)
                row.update(max_penetration(pred.pos, traj.radius, traj.planes, traj.plane_kind))
                rows.append(row)
                if pred.fps is not None:
                    fps.append(float(pred.fps))
        finally:
            simulator.train(was_training)
        return rows, fps

    def shared_rollouts(self, simulator, trajectories: list) -> tuple[list[dict], list[float]]:
        """:meth:`rollout_metrics` of ``trajectories``; under DDP each process rolls out its
        share and gathers the others' rows, so every process returns the same rows."""
        world = dist.get_world_size() if dist.is_available() and dist.is_initialized() else 1
        if world == 1:
            return self.rollout_metrics(simulator, trajectories)
        mine = trajectories[dist.get_rank() :: world]
        share = self.rollout_metrics(simulator, mine) if mine else ([], [])
        parts: list = [None] * world
        dist.all_gather_object(parts, share)
        rows: list = [None] * len(trajectories)
        for rank, (part, _) in enumerate(parts):
            rows[rank::world] = part
        return rows, [f for _, fps in parts for f in fps]

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

    def score_terms(self, rows: list[dict], length_scale: float) -> dict[str, float]:
        """``val/rollout_score`` (module doc) and its physics terms, means over ``rows``
        (:func:`~physgnn.metrics.trajectory_metrics` + :func:`~physgnn.metrics.max_penetration`
        of each rollout up to the horizon); ``length_scale`` d (m), the mean sphere diameter.
        Infinite when a rollout diverged before the horizon (it has no MSE there)."""
        w_depth, w_tunnel, w_rest = self.weights
        depth = [r["max_pen_sphere"] + max(r["max_pen_ground"], r["max_pen_static"]) for r in rows]
        tunnel = [r["tunnelled"] / max(r["n_spheres"], 1) for r in rows]
        rest = [r["rest_drift"] or 0.0 for r in rows]
        at_horizon = [r[f"mse{self.horizon}"] for r in rows]
        if any(r["diverged_at"] is not None for r in rows) or None in at_horizon:
            score = float("inf")
        else:
            score = np.mean(at_horizon) / length_scale**2 + w_depth * np.mean(depth)
            score += w_tunnel * np.mean(tunnel) + w_rest * np.mean(rest)
        return {
            "val/rollout_score": float(score),
            "val/max_depth": float(np.mean(depth)),
            "val/tunnelled": float(np.mean(tunnel)),
            "val/rest_drift": float(np.mean(rest)),
        }

    def log_rollouts(self, pl_module: L.LightningModule, data_dir: Path) -> dict[str, float]:
        """Roll out, log with ``pl_module.log`` and return what was logged."""
        values: dict[str, float] = {}
        all_fps: list[float] = []
        val_keys = VAL_KEYS | {f"mse{self.horizon}": f"val/mse{self.horizon}"}
        groups = [("val", val_keys)] + ([("ood", OOD_KEYS)] if self.ood else [])
        history = hooks_of(pl_module.simulator).history
        with torch.inference_mode():
            for split, keys in groups:
                trajs = self._trajectories(data_dir, split)
                if not trajs:
                    continue
                if split == "val":
                    trajs = self.to_horizon(trajs, history)
                rows, fps = self.shared_rollouts(pl_module.simulator, trajs)
                all_fps += fps
                for key, name in keys.items():
                    vals = [r[key] for r in rows if r[key] is not None]
                    if vals:
                        values[name] = float(np.mean(vals))
                if split == "val":
                    diameter = float(np.mean(np.concatenate([2 * t.radius for t in trajs])))
                    values |= self.score_terms(rows, diameter)
                    self._score = values["val/rollout_score"]
                if split == "ood":
                    values["ood/diverged"] = float(
                        np.mean([r["diverged_at"] is not None for r in rows])
                    )
        if all_fps:
            values["rollout/fps"] = float(np.mean(all_fps))
        for name, value in values.items():  # the same in every DDP process: nothing to sync
            pl_module.log(name, value, on_step=False, on_epoch=True, sync_dist=False)
        return values
