"""Simulate one YAML scene file (``python -m physgnn.simulate``; the command is thin).

Simulates the scene (:mod:`physgnn.groundtruth.scenefile`) with pybullet and, given a trained
run, rolls the learned simulator out from the same start (its first H+1 ground-truth frames,
as ``make eval`` does). Writes into ``out`` (default ``${paths.outputs}/simulate/<scene name>``,
``paths.outputs`` read as every command reads it: ``paths.outputs=``, else ``PHYSGNN_OUTPUTS``,
else ``outputs``):

- ``simulate.h5``: the dataset schema (:mod:`physgnn.data.dataset`), group ``truth`` and,
  with a run, group ``prediction`` (its finite prefix if it diverged);
- ``metrics.json``: the metrics of the prediction against the truth (``make eval``'s
  columns), or the truth's own physics (energy gain, penetration) without a run;
- ``video.gif`` / ``video.mp4``: truth (left) and prediction (right; the truth again without
  a run) side by side (:mod:`physgnn.evaluation.video3d`);
- with ``constraints=N`` (N ≥ 1) the learned step is followed by N iterations of the
  constraint stage (:mod:`physgnn.models.constrained`), recorded in ``metrics.json``;
- with ``rerun=FILE.rrd``: both as a Rerun recording (:mod:`physgnn.evaluation.rerun_log`,
  the optional ``rerun`` extra).

A folder ``out`` that holds files physgnn did not write is refused unless ``overwrite=true``
(:func:`physgnn.files.claim_folder`; the folders it makes carry its marker).

Arguments are ``key=value`` over :data:`KEYS` (not Hydra: ``scene=`` names a file here, where
Hydra would read the ``scene`` config group).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from physgnn import CONF_DIR, metrics
from physgnn.data.dataset import write_split
from physgnn.errors import PhysgnnError
from physgnn.evaluation import rerun_log
from physgnn.evaluation.video3d import render_side_by_side
from physgnn.files import claim_folder, write_json
from physgnn.groundtruth.engine import simulate as engine_simulate
from physgnn.groundtruth.scenefile import load_scene
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout
from physgnn.training.runs import load_run

KEYS = {
    "scene": None,
    "run": None,
    "out": None,
    "video": "true",
    "frames": None,
    "tol": "0",
    "rerun": None,
    "paths.outputs": None,
    "overwrite": "false",
    "constraints": "0",
}
METRIC_KEYS = ("mse", "mse20", "chamfer", "energy_gain", "rotation_error", "diverged_at")


class SimulateError(PhysgnnError, ValueError):
    """Bad command line (one line naming the problem)."""


def parse_args(argv: list[str]) -> DictConfig:
    """``key=value`` arguments over :data:`KEYS` defaults."""
    args = dict(KEYS)
    for item in argv:
        key, eq, value = item.partition("=")
        if not eq or key not in KEYS:
            raise SimulateError(f"bad argument '{item}'; use key=value with keys {list(KEYS)}")
        args[key] = value
    if not args["scene"]:
        raise SimulateError("missing scene=FILE (a YAML scene file, e.g. conf/scenes/throw.yaml)")
    cfg = OmegaConf.create()
    for key, value in args.items():
        OmegaConf.update(cfg, key, value)  # paths.outputs -> cfg.paths.outputs
    return cfg


def outputs_root(args: DictConfig | dict) -> Path:
    """``paths.outputs`` as every command reads it (``conf/paths/default.yaml``): the argument
    ``paths.outputs=``, else ``$PHYSGNN_OUTPUTS``, else ``outputs``."""
    paths = OmegaConf.load(Path(CONF_DIR) / "paths" / "default.yaml")
    given = (args.get("paths") or {}).get("outputs")
    if given:
        paths.outputs = given
    return Path(paths.outputs)


def flag(args: DictConfig | dict, key: str) -> bool:
    """The argument ``key``, ``true`` or ``false`` (any case)."""
    value = args.get(key, KEYS[key])
    if str(value).lower() not in ("true", "false"):
        raise SimulateError(f"{key} must be true or false, got '{value}'")
    return str(value).lower() == "true"


def rollout_prediction(simulator, truth: Trajectory) -> Trajectory:
    """The simulator's rollout of ``truth`` from its first H+1 frames (finite prefix)."""
    return rollout(simulator, [truth])[0]


def learned(run_dir: str, truth: Trajectory, constraints: int = 0) -> tuple[Trajectory, str]:
    """Roll the run's simulator out on ``truth`` (with ``constraints`` > 0, followed by the
    constraint stage, :mod:`physgnn.models.constrained`); returns the prediction and its
    checkpoint."""
    if not Path(run_dir).is_dir():
        raise SimulateError(f"run folder {run_dir} does not exist")
    simulator, _, info = load_run(run_dir)
    if constraints > 0:
        simulator = ConstrainedSimulator(simulator, constraints)
    return rollout_prediction(simulator, truth), str(info.get("checkpoint", run_dir))


def iterations(args: DictConfig | dict) -> int:
    """The argument ``constraints``: a whole number >= 0 (0: the pure learned model)."""
    value = str(args.get("constraints", KEYS["constraints"]))
    if not value.isdigit():
        raise SimulateError(f"constraints must be a whole number >= 0 (iterations), got '{value}'")
    return int(value)


def scene_metrics(truth: Trajectory, pred: Trajectory | None, tol: float) -> dict:
    """Prediction vs truth (``pred``), or the truth's own physics (``pred`` None)."""
    mine = pred if pred is not None else truth.with_finite_velocities()
    m = metrics.trajectory_metrics(mine, truth, tol=tol, horizon=20)
    keys = (*METRIC_KEYS, *metrics.PENETRATION_KEYS) if pred is not None else (
        "energy_gain", *metrics.PENETRATION_KEYS)  # fmt: skip
    out = {k: m.get(k) for k in keys}
    return {k: (None if v is None else float(v)) for k, v in out.items()}


def simulate(args: DictConfig | dict) -> dict:
    """Simulate, roll out, write the files; returns what was written and the metrics."""
    steps = iterations(args)
    scene = load_scene(args["scene"])
    if args["rerun"]:
        rerun_log.require()  # before the work, not after it
    if args["frames"]:
        scene.n_frames = int(args["frames"])
    out = Path(args["out"] or outputs_root(args) / "simulate" / scene.name)
    claim_folder(out, "out", overwrite=flag(args, "overwrite"), ours=not args["out"])
    truth = engine_simulate(scene)
    truth.attrs.update(
        group="truth", scene=scene.name, scene_config=Path(args["scene"]).read_text()
    )
    pred, source = (None, "") if not args["run"] else learned(args["run"], truth, steps)
    trajs = [truth]
    if pred is not None:
        attrs = {**truth.attrs, "group": "prediction", "diverged_at": pred.diverged_at}
        attrs["constraints"] = steps
        trajs.append(dataclasses.replace(pred, attrs=attrs))
    h5 = write_split(out / "simulate.h5", trajs, {"split": "simulate", "preset": scene.name})
    result = {
        "scene": scene.name,
        "n_spheres": scene.n_spheres,
        "n_frames": scene.n_frames,
        "run": source or None,
        "constraints": steps,
        "metrics": scene_metrics(truth, pred, float(args["tol"])),
        "files": {"hdf5": str(h5)},
    }
    if flag(args, "video"):
        result["files"].update(write_videos(out, truth, pred, bool(source)))
    if args["rerun"]:
        result["files"]["rerun"] = str(rerun_log.log_rerun(args["rerun"], truth, pred))
    write_json(out / "metrics.json", result)
    return result


run = simulate


def write_videos(out: Path, truth: Trajectory, pred: Trajectory | None, learned: bool) -> dict:
    label = "prediction" if learned else "ground truth (no run given)"
    return render_side_by_side(out / "video", truth, truth if pred is None else pred,
                               right_label=label, title=truth.attrs.get("scene", ""))  # fmt: skip


def summary(result: dict) -> str:
    """What ``python -m physgnn.simulate`` prints: the metrics, then the files."""
    m = ", ".join(f"{k} {v:.3g}" for k, v in result["metrics"].items() if v is not None)
    lines = [f"{result['scene']}: {result['n_spheres']} spheres, {result['n_frames']} frames; {m}"]
    lines += [f"  {kind}: {path}" for kind, path in result["files"].items()]
    return "\n".join(lines)
