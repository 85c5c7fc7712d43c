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

A folder ``out`` that holds files physgnn did not write is refused unless ``overwrite=true``
(:func:`physgnn.files.claim_folder`; the folders it makes carry its marker). One simulate
writes into an ``out`` at a time, through a staging folder: ``out`` holds one scene's files,
whole, and an interrupted run leaves it as it was.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import yaml
from omegaconf import DictConfig
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn import metrics
from physgnn.data.dataset import write_split
from physgnn.errors import PhysgnnError, check_flag, check_whole, disk_problem, one_line
from physgnn.evaluation import rerun_log
from physgnn.evaluation.ood import outside, warning_text
from physgnn.evaluation.video3d import render_side_by_side
from physgnn.files import claim_folder, portable, staged_outputs, write_json
from physgnn.groundtruth.engine import simulate as engine_simulate
from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.scenefile import load_scene, scene_file, scene_to_dict
from physgnn.metrics import check_tolerance
from physgnn.metrics.checks import frames as checked_frames
from physgnn.metrics.names import scene_columns
from physgnn.models.capture import compile_simulator, compiled_graphs
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.physics.scene import Scene
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout
from physgnn.training.runs import load_run, resolve_run

# What a simulate writes into its out (replaced whole by the next one).
SIMULATE_OUTPUTS = ("simulate.h5", "metrics.json", "video.gif", "video.mp4", "video_frame.png")


class SimulateError(PhysgnnError, ValueError):
    """Bad command line (one line naming the problem)."""


def scene_of(cfg: DictConfig) -> tuple[Scene, str]:
    """The scene ``cfg`` names (``scene=`` or ``scene_file=``, exactly one) with ``frames``
    applied, and its scene file's text (the provenance of the truth)."""
    group, path = cfg.get("scene"), cfg.get("scene_file")
    if (group is None) == (path is None):
        how = "both given: give one" if group is not None else "missing"
        raise SimulateError(
            f"scene: {how} (scene=NAME: an example or a scene family of conf/scene/, e.g. "
            "scene=throw; scene_file=PATH: a YAML scene file of yours)"
        )
    if path is not None:
        scene, text = load_scene(path), scene_file(path).read_text()
    else:
        seed = whole(cfg, "seed", 0, "the draw of a scene family")
        scene = build_scene(group, np.random.default_rng(seed))
        text = yaml.safe_dump(scene_to_dict(scene), sort_keys=False)  # the scene as drawn
    if cfg.get("frames") is not None:
        scene.n_frames = whole(cfg, "frames", 2, "the first frame is the start; e.g. frames=100")
    return scene, text


def whole(cfg: DictConfig, key: str, least: int, what: str) -> int:
    """The whole number ``cfg[key]``, at least ``least``; else one line naming the key."""
    return check_whole(key, cfg.get(key), least, what, SimulateError)


def flag(cfg: DictConfig, key: str) -> bool:
    """The argument ``key``: true or false."""
    return check_flag(key, cfg.get(key), SimulateError)


def rollout_prediction(simulator, truth: Trajectory) -> Trajectory:
    """The simulator's rollout of ``truth`` from its first H+1 frames (finite prefix)."""
    return rollout(simulator, [truth])[0]


def learned(
    run_dir: str, truth: Trajectory, constraints: int = 0, compile_cache: str | None = None
) -> tuple[Trajectory, dict]:
    """Roll the run's simulator out on ``truth`` (with ``constraints`` > 0, followed by the
    constraint stage, :mod:`physgnn.models.constrained`; with a ``compile_cache`` folder,
    compiled, :func:`compile_ahead`); returns the prediction and where it came from:
    ``{"checkpoint", "run", "H", "constraints", "ms_per_frame", "compile_s", "cfg"}``."""
    folder = resolve_run(run_dir)
    if not folder.is_dir():
        raise SimulateError(f"run folder {run_dir} does not exist")
    simulator, cfg, info = load_run(folder)
    history = int(simulator.H)
    fresh = compile_cache is not None and not any(Path(compile_cache).glob("*"))
    compile_s = None
    with compile_guard(compile_cache):
        if compile_cache is not None:
            compile_s = compile_ahead(simulator, truth, compile_cache)
        if constraints > 0:
            simulator = ConstrainedSimulator(simulator, constraints)
        if truth.n_spheres * truth.n_frames >= LONG:
            print(
                f"rolling the learned simulator out: {truth.n_spheres} spheres, {truth.n_frames} "
                "frames ...",
                file=sys.stderr,
                flush=True,
            )
        graphs = compiled_graphs()
        start = time.perf_counter()
        pred = rollout_prediction(simulator, truth)
    steps = max(pred.n_frames - history - 1, 1)
    graphs = compiled_graphs() - graphs
    if compile_s is not None and graphs > 0 and fresh:  # a second call loaded them: no note
        print(
            f"note: ms_per_frame includes compiling {graphs} more graph(s) "
            "for edge counts the first frames did not have (0 or 1 pair); a second call "
            "loads them from paths.compile_cache",
            file=sys.stderr,
        )
    source = {"checkpoint": str(info.get("checkpoint", run_dir)), "run": portable(folder)}
    source |= {"H": history, "constraints": constraints, "cfg": cfg, "compile_s": compile_s}
    source["ms_per_frame"] = 1000 * (time.perf_counter() - start) / steps
    return pred, source


@contextmanager
def compile_guard(cache_dir: str | None) -> Iterator[None]:
    """With a compile cache (``cache_dir``; None: nothing guarded), a failing compile is one
    line naming ``paths.compile_cache``: a full, read-only or forbidden one (the files this
    compile left there removed), or one that may be corrupt (truncated ``.so`` files), with
    how to clear it."""
    if cache_dir is None:
        yield
        return
    cache = Path(cache_dir)
    before = set(cache.rglob("*")) if cache.is_dir() else set()
    try:
        yield
    except (PhysgnnError, KeyboardInterrupt):
        raise
    except Exception as err:
        failed = err
    else:
        return
    disk = next((e for e in _chain(failed) if disk_problem(e)), None)
    what = f"{type(failed).__name__}: {one_line(failed)}"[:300]
    reason = disk and (getattr(disk, "strerror", None) or "disk full or read-only")
    del failed, disk  # their frames hold the compiler's open files
    if reason is None:
        raise SimulateError(
            f"compiling the learned step failed ({what}); the compile cache "
            f"paths.compile_cache={cache} may be corrupt (truncated files): clear it (rm -r "
            f"{cache}) and run again, or run with compile=false"
        )
    for path in sorted(set(cache.rglob("*")) - before, reverse=True):  # files, then folders
        try:
            path.unlink() if path.is_file() or path.is_symlink() else path.rmdir()
        except OSError:
            pass
    raise SimulateError(
        f"paths.compile_cache={cache} cannot be written ({reason}; what this compile wrote "
        "there was removed): free space there, or choose a writable paths.compile_cache (or "
        "compile=false)"
    )


def _chain(err: BaseException) -> Iterator[BaseException]:
    """``err`` and the errors it was raised from or during (inductor wraps a failed write)."""
    seen = set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        yield err
        err = err.__cause__ or err.__context__


def compile_ahead(simulator, truth: Trajectory, cache_dir: str) -> float:
    """Seconds to compile ``simulator``'s step (:func:`~physgnn.models.capture.compile_simulator`,
    its code kept in ``cache_dir``) on a few frames of ``truth``, so that the timed rollout
    after it runs compiled code only."""
    print("compiling the learned step ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    compile_simulator(simulator, cache_dir=cache_dir)
    rollout(simulator, [truth.truncated(min(int(simulator.H) + 3, truth.n_frames))])
    return time.perf_counter() - start


def scene_metrics(truth: Trajectory, pred: Trajectory | None, tol: float) -> dict:
    """Prediction vs truth (``pred``), or the truth's own physics (``pred`` None). A diverged
    prediction has no metrics (None) but ``diverged_at``: its finite prefix would read as a
    good rollout."""
    checked_frames(truth.pos, "truth pos")  # named as the truth's, before a copy of it is measured
    mine = pred if pred is not None else truth.with_finite_velocities()
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
    steps = whole(cfg, "constraints", 0, "iterations; 0: the learned model alone")
    tol, video, overwrite = tolerance(cfg), flag(cfg, "video"), flag(cfg, "overwrite")
    scene, text = scene_of(cfg)
    if cfg.get("rerun"):
        rerun_log.require()  # before the work, not after it
    out = Path(cfg.get("out") or Path(cfg.paths.outputs) / "simulate" / scene.name)
    claim_folder(out, "out", overwrite=overwrite, ours=not cfg.get("out"))
    with staged_outputs(out, "out", SIMULATE_OUTPUTS) as staging:
        return _simulate_into(cfg, (scene, text), (staging, out), (steps, tol, video))


def _simulate_into(cfg, scene_text, folders: tuple[Path, Path], how: tuple) -> dict:
    """:func:`simulate`'s work, its files written into the staging folder and named in the
    result as they will lie in ``out`` (``folders``: staging, out; ``how``: constraint
    iterations, penetration tolerance, video)."""
    (scene, text), (out, final), (steps, tol, video) = scene_text, folders, how
    start = time.perf_counter()
    truth = simulate_with_progress(scene)
    truth.attrs.update(
        group="truth",
        scene=scene.name,
        scene_config=text,
        velocity="the engine's (pybullet)",
        ms_per_frame=1000 * (time.perf_counter() - start) / max(scene.n_frames - 1, 1),
    )
    cache = cfg.paths.compile_cache if cfg.compile else None
    pred, source = (None, {}) if not cfg.get("run") else learned(str(cfg.run), truth, steps, cache)
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
        "constraints": steps,
        "compile_s": source.get("compile_s"),
        "warnings": warnings,
        "ms_per_frame": {
            "pybullet": truth.attrs["ms_per_frame"],
            "learned": source.get("ms_per_frame"),
        },
        "metrics": scene_metrics(truth, pred, tol),
        "files": {"hdf5": str(h5)},
    }
    if video:
        result["files"].update(write_videos(out, truth, pred, bool(source)))
    result["files"] = {k: str(final / Path(v).name) for k, v in result["files"].items()}
    if cfg.get("rerun"):
        result["files"]["rerun"] = str(rerun_log.log_rerun(cfg.rerun, truth, pred))
    write_json(out / "metrics.json", result)
    return result


def tolerance(cfg: DictConfig) -> float:
    """The argument ``tol``: a number >= 0 (a fraction of the diameter; 0: any overlap)."""
    return check_tolerance(cfg.get("tol"), SimulateError)


# Above this many sphere-frames a simulation shows its progress (it takes more than seconds).
LONG = 100_000


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
        "velocity": "finite differences of the predicted positions",
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
