"""``python -m physgnn.sleep_study run=PATH``: sleeping off against on for a trained run.

Rolls out OOD (c) ``ood_resting_hit`` (from the run's dataset) and the stability suite's
``resting_pile`` (touching spheres at rest on the ground, which must stay still; simulated by
pybullet) with ``rollout.sleeping`` off and on, and reports per scene: rest drift
(:func:`physgnn.metrics.drift_before_hit`: displacement, in radii, of a sphere the ground truth
keeps still, over the frames before the truth moves it; max and mean over those spheres),
position MSE, Chamfer distance, MSE at 20 frames, the share of frozen (asleep) sphere-steps and
ms per frame. Writes ``<out>/sleep_study.json`` and prints a markdown table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from physgnn import metrics
from physgnn.data.dataset import read_split
from physgnn.errors import ConfigError
from physgnn.evaluation.runs import dataset_of
from physgnn.files import claimed, write_json
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import build_scene
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout
from physgnn.training.runs import load_run

# The default out (conf/sleep_study.yaml), under paths.outputs: physgnn's own folder.
DEFAULT_OUT = "sleep_study"
COLUMNS = (
    "scene",
    "sleeping",
    "rest_drift",
    "rest_drift_mean",
    "mse",
    "mse20",
    "chamfer",
    "frozen_pct",
    "ms_per_frame",
    "diverged_at",
)


def resting_pile(cfg: DictConfig) -> Trajectory:
    """The stability suite's ``resting_pile`` scene (``cfg.pile``) simulated by pybullet."""
    return simulate(build_scene(cfg.pile, np.random.default_rng(int(cfg.seed))), None)


def frozen_share(pos: np.ndarray, start: int) -> float:
    """Percentage of sphere-steps after ``start`` whose position did not change at all: the
    sleeping ones (a learned model never keeps an awake sphere exactly still)."""
    if pos.shape[0] <= start + 1:
        return 0.0
    same = (pos[start + 1 :] == pos[start:-1]).all(-1)
    return float(100.0 * same.mean())


def compare(simulator, traj: Trajectory, sleep: dict) -> list[dict]:
    """Rows (``COLUMNS``) of ``traj`` rolled out with sleeping off, then on."""
    rows = []
    for on in (False, True):
        (res,) = rollout(simulator, [traj], sleep=sleep if on else False)
        m = metrics.trajectory_metrics(res, traj, horizon=20)
        drift = metrics.drift_before_hit(res.pos, traj.pos, traj.radius, res.start)
        rows.append(
            dict(
                scene=traj.name,
                sleeping="on" if on else "off",
                rest_drift=float(drift.max()) if drift.size else None,
                rest_drift_mean=float(drift.mean()) if drift.size else None,
                mse=m["mse"],
                mse20=m["mse20"],
                chamfer=m["chamfer"],
                frozen_pct=frozen_share(res.pos, res.start),
                ms_per_frame=1000.0 / res.fps if res.fps else 0.0,
                diverged_at=res.diverged_at,
            )
        )
    return rows


def markdown(rows: list[dict]) -> str:
    def cell(v):
        return "—" if v is None else f"{v:.3g}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(cell(r[c]) for c in COLUMNS) + " |" for r in rows]
    return "\n".join(lines)


def study(cfg: DictConfig) -> list[dict]:
    """Load ``cfg.run``, compare sleeping off/on on OOD (c) and the pile; write the JSON. An
    ``out`` holding files physgnn did not write is refused before the work
    (:func:`physgnn.files.claim_folder`; the default folder is physgnn's); a study that fails
    leaves no folder it made (:func:`physgnn.files.claimed`)."""
    if not cfg.run:
        raise ConfigError("pass run=PATH (a finished training run folder)")
    out = Path(cfg.out)
    with claimed(out, "out", overwrite=None, ours=out == Path(cfg.paths.outputs) / DEFAULT_OUT):
        return _study_into(cfg, out)


def _study_into(cfg: DictConfig, out: Path) -> list[dict]:
    """:func:`study`'s work, its JSON written into ``out``."""
    torch.set_num_threads(int(cfg.threads))
    simulator, run_cfg, _ = load_run(cfg.run)
    dataset = Path(cfg.dataset) if cfg.dataset else dataset_of(run_cfg)
    scenes = [t for t in read_split(dataset / "ood.h5") if t.name == "ood_resting_hit"]
    if cfg.max_frames:
        scenes = [t.truncated(cfg.max_frames) for t in scenes]
    scenes.append(resting_pile(cfg))
    sleep = OmegaConf.to_container(cfg.sleep)
    rows = [row for traj in scenes for row in compare(simulator, traj, sleep)]
    meta = {"run": str(cfg.run), "dataset": str(dataset), "sleep": sleep}
    write_json(out / "sleep_study.json", {**meta, "rows": rows})
    return rows
