"""Simulate one scene (``python -m physgnn.simulate``, config ``conf/simulate.yaml``; the
command is thin).

The scene is ``scene=NAME``, an entry of the ``scene`` config group (``conf/scene/``: an
example scene file such as ``throw``, or a scene family such as ``ood_cubes``, of which one
scene is drawn with ``seed``), or ``scene_file=PATH``, a YAML scene file
(:mod:`physgnn.groundtruth.scenefile`). It simulates the scene with pybullet and, given a
trained run (``run=``, a folder or ``pretrained``), rolls the learned simulator out from the
same start (its first H+1 ground-truth frames, as ``make eval`` does). Writes into ``out``
(default ``${paths.outputs}/simulate/<scene name>``):

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

The options are one typed group checked before any work (:class:`SimulateOptions`); the
learned rollout, compiled on request, is :mod:`physgnn.evaluation.simulate_learned`.

A folder ``out`` that holds files physgnn did not write is refused unless ``overwrite=true``
(:func:`physgnn.files.claim_folder`; the folders it makes carry its marker, and go again when it
fails before writing, :func:`physgnn.files.claimed`). One simulate
writes into an ``out`` at a time, through a staging folder: ``out`` holds one scene's files,
whole, and an interrupted run leaves it as it was.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from omegaconf import DictConfig
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn import metrics
from physgnn.data.dataset import write_split
from physgnn.evaluation import rerun_log
from physgnn.evaluation.ood import outside, warning_text
from physgnn.evaluation.simulate_learned import LONG, learned
from physgnn.evaluation.simulate_options import SimulateOptions
from physgnn.evaluation.video3d import render_side_by_side
from physgnn.files import claimed_outputs, write_json
from physgnn.groundtruth.engine import simulate as engine_simulate
from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.scenefile import load_scene, scene_file, scene_to_dict
from physgnn.metrics.checks import frames as checked_frames
from physgnn.metrics.names import scene_columns
from physgnn.physics.scene import Scene
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import VELOCITY

# What a simulate writes into its out (replaced whole by the next one).
SIMULATE_OUTPUTS = ("simulate.h5", "metrics.json", "video.gif", "video.mp4", "video_frame.png")


def scene_of(options: SimulateOptions) -> tuple[Scene, str]:
    """The scene of ``options`` (``scene=`` or ``scene_file=``) with ``frames`` applied, and
    its scene file's text (the provenance of the truth)."""
    if options.scene_file is not None:
        path = options.scene_file
        scene, text = load_scene(path), scene_file(path).read_text()
    else:
        scene = build_scene(options.scene, np.random.default_rng(options.seed))
        text = yaml.safe_dump(scene_to_dict(scene), sort_keys=False)  # the scene as drawn
    if options.frames is not None:
        scene.n_frames = options.frames
    return scene, text


def scene_metrics(truth: Trajectory, pred: Trajectory | None, tol: float) -> dict:
    """Prediction vs truth (``pred``), or the truth's own physics (``pred`` None). A diverged
    prediction has no metrics (None) but ``diverged_at``: its finite prefix would read as a
    good rollout."""
    checked_frames(truth.pos, "truth pos")  # named as the truth's, before a copy of it is measured
    mine = (pred if pred is not None else truth).with_finite_velocities()  # energy alike
    m = metrics.trajectory_metrics(mine, truth, tol=tol, horizon=20)
    keys = scene_columns(prediction=pred is not None)
    out = {k: m.get(k) for k in keys}
    if pred is not None and pred.diverged_at is not None:
        out = dict.fromkeys(keys) | {"diverged_at": pred.diverged_at}
    return {k: (None if v is None else float(v)) for k, v in out.items()}


def simulate(cfg: DictConfig) -> dict:
    """Simulate, roll out, write the files; returns what was written and the metrics. One
    simulate at a time per ``out``; its files replace the previous ones whole
    (:func:`physgnn.files.staged_outputs`): an interrupted run leaves ``out`` as it was."""
    options = SimulateOptions.of(cfg)
    scene, text = scene_of(options)
    if options.rerun:
        rerun_log.require()  # before the work, not after it
    out = Path(options.out or Path(options.outputs) / "simulate" / scene.name)
    overwrite, ours = options.overwrite, not options.out
    with claimed_outputs(out, "out", SIMULATE_OUTPUTS, overwrite, ours) as staging:
        return _simulate_into(options, Scenario(scene, text), Folders(staging, out))


@dataclass(frozen=True)
class Scenario:
    """The scene simulated and its scene file's text (the truth's provenance)."""

    scene: Scene
    text: str


@dataclass(frozen=True)
class Folders:
    """Where a simulate writes (``staging``) and where its files will lie (``out``)."""

    staging: Path
    out: Path


def _simulate_into(options: SimulateOptions, scenario: Scenario, folders: Folders) -> dict:
    """:func:`simulate`'s work, its files written into the staging folder and named in the
    result as they will lie in ``out``."""
    scene, out = scenario.scene, folders.staging
    truth = simulated_truth(scenario)
    pred, source = (None, {})
    if options.run:
        run = str(options.run)
        pred, source = learned(run, truth, options.constraints, options.cache, options.threads)
    warnings = outside(scene, source.get("cfg")) if pred is not None else []
    if warnings:
        print(f"warning: {warning_text(scene.name, warnings)}", file=sys.stderr)
    trajs = [truth] if pred is None else [truth, with_provenance(pred, truth, source)]
    h5 = write_split(out / "simulate.h5", trajs, {"split": "simulate", "preset": scene.name})
    result = {
        "scene": scene.name,
        "n_spheres": scene.n_spheres,
        "n_frames": scene.n_frames,
        "run": source.get("checkpoint"),
        "constraints": options.constraints,
        "compile_s": source.get("compile_s"),
        "threads": source.get("threads"),
        "warnings": warnings,
        "ms_per_frame": {
            "pybullet": truth.attrs["ms_per_frame"],
            "learned": source.get("ms_per_frame"),
        },
        "metrics": scene_metrics(truth, pred, options.tol),
        "files": {"hdf5": str(h5)},
    }
    if options.video:
        result["files"].update(write_videos(out, truth, pred, bool(source)))
    result["files"] = {k: str(folders.out / Path(v).name) for k, v in result["files"].items()}
    if options.rerun:
        result["files"]["rerun"] = str(rerun_log.log_rerun(options.rerun, truth, pred))
    write_json(out / "metrics.json", result)
    return result


def simulated_truth(scenario: Scenario) -> Trajectory:
    """pybullet's trajectory of the scene, with what made it in its attributes."""
    start = time.perf_counter()
    truth = simulate_with_progress(scenario.scene)
    truth.attrs.update(
        group="truth",
        scene=scenario.scene.name,
        scene_config=scenario.text,
        velocity="the engine's (pybullet)",
        ms_per_frame=1000 * (time.perf_counter() - start) / max(scenario.scene.n_frames - 1, 1),
    )
    return truth


def simulate_with_progress(scene) -> Trajectory:
    """pybullet's run of ``scene``; when it is long, a line saying so and a progress bar on
    the terminal."""
    if scene.n_spheres * scene.n_frames < LONG:
        return engine_simulate(scene)
    # a line: the bar below shows on a terminal only
    print(
        f"simulating with pybullet: {scene.n_spheres} spheres, {scene.n_frames} frames ...",
        file=sys.stderr,
        flush=True,
    )
    columns = (TextColumn("pybullet"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, transient=True) as bar:
        task = bar.add_task("frames", total=scene.n_frames)
        return engine_simulate(scene, on_frame=lambda done: bar.update(task, completed=done))


def with_provenance(pred: Trajectory, truth: Trajectory, source: dict) -> Trajectory:
    """The prediction with attributes that say what made it (not the truth's engine's):
    the run, its checkpoint, H, the constraint iterations, ``diverged_at`` (-1: it did not),
    how its velocities were obtained and ms per frame."""
    attrs = {
        "group": "prediction",
        "scene": truth.attrs.get("scene", truth.name),
        "scene_config": truth.attrs.get("scene_config", ""),
        "made_by": "physgnn learned simulator",
        "run": source.get("run", ""),
        "checkpoint": Path(source.get("checkpoint", "")).name,
        "H": source.get("H", -1),
        "constraints": source.get("constraints", 0),
        "diverged_at": -1 if pred.diverged_at is None else int(pred.diverged_at),
        "velocity": pred.attrs.get("velocity", VELOCITY[False]),
        "ms_per_frame": source.get("ms_per_frame", -1.0),
    }
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
        m = (
            f"the prediction DIVERGED at frame {int(metrics_['diverged_at'])}: no metrics "
            "(its frames before that would read as a good rollout)"
        )
    lines = [f"{result['scene']}: {result['n_spheres']} spheres, {result['n_frames']} frames; {m}"]
    lines += [f"  {kind}: {path}" for kind, path in result["files"].items()]
    return "\n".join(lines)
