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
(:func:`physgnn.files.claim_folder`; the folders it makes carry its marker). One simulate
writes into an ``out`` at a time, through a staging folder: ``out`` holds one scene's files,
whole, and an interrupted run leaves it as it was.

Arguments are ``key=value`` over :data:`KEYS` (not Hydra: ``scene=`` names a file here, where
Hydra would read the ``scene`` config group).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from pathlib import Path

from omegaconf import DictConfig, OmegaConf
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn import CONF_DIR, metrics
from physgnn.data.dataset import write_split
from physgnn.errors import PhysgnnError
from physgnn.evaluation import rerun_log
from physgnn.evaluation.ood import outside, warning_text
from physgnn.evaluation.video3d import render_side_by_side
from physgnn.files import claim_folder, portable, staged_outputs, write_json
from physgnn.groundtruth.engine import simulate as engine_simulate
from physgnn.groundtruth.scenefile import load_scene, scene_file
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout
from physgnn.training.runs import load_run, resolve_run

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
# What a simulate writes into its out (replaced whole by the next one).
SIMULATE_OUTPUTS = ("simulate.h5", "metrics.json", "video.gif", "video.mp4", "video_frame.png")
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
        raise SimulateError("missing scene=FILE (a YAML scene file, or an example: scene=throw)")
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


def learned(run_dir: str, truth: Trajectory, constraints: int = 0) -> tuple[Trajectory, dict]:
    """Roll the run's simulator out on ``truth`` (with ``constraints`` > 0, followed by the
    constraint stage, :mod:`physgnn.models.constrained`); returns the prediction and where it
    came from: ``{"checkpoint", "run", "H", "constraints", "ms_per_frame", "cfg"}``."""
    folder = resolve_run(run_dir)
    if not folder.is_dir():
        raise SimulateError(f"run folder {run_dir} does not exist")
    simulator, cfg, info = load_run(folder)
    history = int(simulator.H)
    if constraints > 0:
        simulator = ConstrainedSimulator(simulator, constraints)
    if truth.n_spheres * truth.n_frames >= LONG:
        print(f"rolling the learned simulator out: {truth.n_spheres} spheres, {truth.n_frames} "
              "frames ...", file=sys.stderr, flush=True)  # fmt: skip
    start = time.perf_counter()
    pred = rollout_prediction(simulator, truth)
    steps = max(pred.n_frames - history - 1, 1)
    source = {"checkpoint": str(info.get("checkpoint", run_dir)), "run": portable(folder)}
    source |= {"H": history, "constraints": constraints, "cfg": cfg}
    source["ms_per_frame"] = 1000 * (time.perf_counter() - start) / steps
    return pred, source


def iterations(args: DictConfig | dict) -> int:
    """The argument ``constraints``: a whole number >= 0 (0: the pure learned model)."""
    value = str(args.get("constraints", KEYS["constraints"]))
    if not value.isdigit():
        raise SimulateError(f"constraints must be a whole number >= 0 (iterations), got '{value}'")
    return int(value)


def scene_metrics(truth: Trajectory, pred: Trajectory | None, tol: float) -> dict:
    """Prediction vs truth (``pred``), or the truth's own physics (``pred`` None). A diverged
    prediction has no metrics (None) but ``diverged_at``: its finite prefix would read as a
    good rollout."""
    mine = pred if pred is not None else truth.with_finite_velocities()
    m = metrics.trajectory_metrics(mine, truth, tol=tol, horizon=20)
    keys = (*METRIC_KEYS, *metrics.PENETRATION_KEYS) if pred is not None else (
        "energy_gain", *metrics.PENETRATION_KEYS)  # fmt: skip
    out = {k: m.get(k) for k in keys}
    if pred is not None and pred.diverged_at is not None:
        out = dict.fromkeys(keys) | {"diverged_at": pred.diverged_at}
    return {k: (None if v is None else float(v)) for k, v in out.items()}


def simulate(args: DictConfig | dict) -> dict:
    """Simulate, roll out, write the files; returns what was written and the metrics. One
    simulate at a time per ``out``; its files replace the previous ones whole
    (:func:`physgnn.files.staged_outputs`): an interrupted run leaves ``out`` as it was."""
    steps, tol = iterations(args), tolerance(args)
    scene = load_scene(args["scene"])
    if args["rerun"]:
        rerun_log.require()  # before the work, not after it
    if args["frames"]:
        scene.n_frames = frame_count(args["frames"])
    out = Path(args["out"] or outputs_root(args) / "simulate" / scene.name)
    claim_folder(out, "out", overwrite=flag(args, "overwrite"), ours=not args["out"])
    with staged_outputs(out, "out", SIMULATE_OUTPUTS) as staging:
        return _simulate_into(args, scene, (staging, out), steps, tol)


def _simulate_into(args, scene, folders: tuple[Path, Path], steps: int, tol: float) -> dict:
    """:func:`simulate`'s work, its files written into the staging folder and named in the
    result as they will lie in ``out`` (``folders``: staging, out)."""
    out, final = folders
    start = time.perf_counter()
    truth = simulate_with_progress(scene)
    truth.attrs.update(
        group="truth", scene=scene.name, scene_config=scene_file(args["scene"]).read_text(),
        velocity="the engine's (pybullet)", ms_per_frame=1000 * (time.perf_counter() - start)
        / max(scene.n_frames - 1, 1),
    )  # fmt: skip
    pred, source = (None, {}) if not args["run"] else learned(args["run"], truth, steps)
    warnings = outside(scene, source.get("cfg")) if pred is not None else []
    if warnings:
        print(f"warning: {warning_text(scene.name, warnings)}", file=sys.stderr)
    trajs = [truth] if pred is None else [truth, with_provenance(pred, truth, source)]
    h5 = write_split(out / "simulate.h5", trajs, {"split": "simulate", "preset": scene.name})
    result = {
        "scene": scene.name, "n_spheres": scene.n_spheres, "n_frames": scene.n_frames,
        "run": source.get("checkpoint"), "constraints": steps, "warnings": warnings,
        "ms_per_frame": {"pybullet": truth.attrs["ms_per_frame"],
                         "learned": source.get("ms_per_frame")},
        "metrics": scene_metrics(truth, pred, tol),
        "files": {"hdf5": str(h5)},
    }  # fmt: skip
    if flag(args, "video"):
        result["files"].update(write_videos(out, truth, pred, bool(source)))
    result["files"] = {k: str(final / Path(v).name) for k, v in result["files"].items()}
    if args["rerun"]:
        result["files"]["rerun"] = str(rerun_log.log_rerun(args["rerun"], truth, pred))
    write_json(out / "metrics.json", result)
    return result


def tolerance(args: DictConfig | dict) -> float:
    """The argument ``tol``: a number >= 0 (a fraction of the diameter; 0: any overlap)."""
    value = str(args.get("tol", KEYS["tol"]))
    try:
        tol = float(value)
    except ValueError:
        tol = float("nan")
    if not math.isfinite(tol) or tol < 0:
        raise SimulateError(
            f"tol must be a number >= 0 (a fraction of the diameter; 0: any overlap counts), "
            f"got '{value}'"
        )
    return tol


def frame_count(value) -> int:
    """The argument ``frames``: a whole number >= 2 (the first frame is the start)."""
    if not str(value).isdigit() or int(value) < 2:
        raise SimulateError(f"frames must be a whole number >= 2, got '{value}' (e.g. frames=100)")
    return int(value)


# Above this many sphere-frames a simulation shows its progress (it takes more than seconds).
LONG = 100_000


def simulate_with_progress(scene) -> Trajectory:
    """pybullet's run of ``scene``, with a progress bar on the terminal when it is long."""
    if scene.n_spheres * scene.n_frames < LONG:
        return engine_simulate(scene)
    columns = (TextColumn("pybullet"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, transient=True) as bar:
        task = bar.add_task("frames", total=scene.n_frames)
        return engine_simulate(scene, on_frame=lambda done: bar.update(task, completed=done))


def with_provenance(pred: Trajectory, truth: Trajectory, source: dict) -> Trajectory:
    """The prediction with attributes that say what made it (not the truth's engine's):
    the run, its checkpoint, H, the constraint iterations, ``diverged_at`` (-1: it did not),
    how its velocities were obtained and ms per frame."""
    attrs = {"group": "prediction", "scene": truth.attrs.get("scene", truth.name),
             "scene_config": truth.attrs.get("scene_config", ""),
             "made_by": "physgnn learned simulator", "run": source.get("run", ""),
             "checkpoint": Path(source.get("checkpoint", "")).name, "H": source.get("H", -1),
             "constraints": source.get("constraints", 0),
             "diverged_at": -1 if pred.diverged_at is None else int(pred.diverged_at),
             "velocity": "finite differences of the predicted positions",
             "ms_per_frame": source.get("ms_per_frame", -1.0)}  # fmt: skip
    return dataclasses.replace(pred, attrs=attrs)


run = simulate


def write_videos(out: Path, truth: Trajectory, pred: Trajectory | None, learned: bool) -> dict:
    label = "prediction" if learned else "ground truth (no run given)"
    panel = (truth if pred is None else pred, label)
    return render_side_by_side(out / "video", truth, [panel], title=truth.attrs.get("scene", ""))


def summary(result: dict) -> str:
    """What ``python -m physgnn.simulate`` prints: the metrics (or the frame a prediction
    diverged at), then the files."""
    metrics_ = result["metrics"]
    m = ", ".join(f"{k} {v:.3g}" for k, v in metrics_.items() if v is not None)
    if metrics_.get("diverged_at") is not None:
        m = (f"the prediction DIVERGED at frame {int(metrics_['diverged_at'])}: no metrics "
             "(its frames before that would read as a good rollout)")  # fmt: skip
    lines = [f"{result['scene']}: {result['n_spheres']} spheres, {result['n_frames']} frames; {m}"]
    lines += [f"  {kind}: {path}" for kind, path in result["files"].items()]
    return "\n".join(lines)
