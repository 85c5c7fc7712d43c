"""physgnn in a notebook: a model, a scene, its truth, a rollout, scores, a film, exports.

```python
import physgnn.api as pg

model = pg.load_model("pretrained")     # the shipped weights, or a run folder
scene = pg.load_scene("throw")          # a YAML scene file, or an example scene's name
truth = pg.simulate(scene, frames=40)   # pybullet's trajectory
pred = pg.roll_out(model, truth)        # the learned rollout from truth's first H+1 frames
pg.score(pred, truth)                   # {"mse": ..., "chamfer": ..., "energy_gain": ...}
pg.animate(truth, pred, "throw")        # throw.gif, throw.mp4, throw_frame.png
pg.export(pred, "throw_vtk", "vtk")     # ParaView; or "gns", "lagrangebench", "hdf5"
```

A scene from arrays: ``pg.scene_from_arrays(pos [N, 3], radius, vel=[N, 3], frames=T)``; a
trajectory from another engine: ``pg.trajectory_from_arrays(pos [T, N, 3], radius, dt)``.
Both take the optional fields of :meth:`~physgnn.physics.trajectory.Trajectory.from_arrays`
(pairs: ``planes=(rows, kinds)``, ``materials=(table, index)``).
A scene outside what the model was trained on makes :func:`roll_out` warn with an
:class:`OutOfDistributionWarning` (``warnings.simplefilter("error", pg.OutOfDistributionWarning)``
turns it into an error). Every trajectory is a :class:`~physgnn.physics.trajectory.Trajectory`.
An argument of the wrong type or out of range is one :class:`ArgumentError` line naming it;
the values are checked by the same functions as the commands' keys (``tol``, ``frames``,
``constraints``; a scene as a scene file's).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from physgnn.data import exports, hdf5_export, interchange, vtk
from physgnn.errors import PhysgnnError
from physgnn.evaluation.ood import outside, warning_text
from physgnn.evaluation.simulate import scene_metrics
from physgnn.evaluation.simulate_options import CONSTRAINTS, FRAMES, THREADS
from physgnn.evaluation.video3d import render_side_by_side
from physgnn.groundtruth import scene_values, scenefile
from physgnn.groundtruth.engine import simulate as engine_simulate
from physgnn.metrics import check_tolerance
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.models.settings import torch_threads
from physgnn.physics.scene import Scene, SceneError
from physgnn.physics.trajectory import Trajectory, scene_at
from physgnn.ranges import whole
from physgnn.rollout import rollout
from physgnn.training.runs import load_run

FORMATS = ("vtk", "gns", "lagrangebench", "hdf5")
FILM = (".gif", ".mp4", "_frame.png")  # the files animate writes, after its stem
trajectory_from_arrays = Trajectory.from_arrays
load_trajectories = hdf5_export.load_trajectories


class OutOfDistributionWarning(UserWarning):
    """A scene outside the ranges the model was trained on: its rollout is extrapolation."""


class ArgumentError(PhysgnnError, TypeError, ValueError):
    """An argument of the wrong type or out of range (one line naming it and the fix)."""


def _of_type(name: str, value, kind: type | tuple, fix: str) -> None:
    """``value`` of the argument ``name`` is a ``kind``; else one line naming it and ``fix``."""
    if not isinstance(value, kind):
        raise ArgumentError(f"{name} must be {fix}, got {type(value).__name__}")


@dataclass
class Model:
    """A trained learned simulator: ``simulator`` (``sim(state) -> (v, ω)``), its run's
    ``cfg`` and ``info`` (run.json and the ``checkpoint`` loaded)."""

    simulator: object
    cfg: DictConfig
    info: dict

    @property
    def H(self) -> int:
        """The model's history: a rollout starts from a trajectory's first H+1 frames."""
        return int(self.simulator.H)


def load_model(run: str | Path = "pretrained") -> Model:
    """The model of a finished run folder, or of the shipped weights (``"pretrained"``); a run
    still training is refused (its checkpoints are mid-run)."""
    _of_type("run", run, (str, Path), "a run folder (str or Path) or 'pretrained'")
    return Model(*load_run(run))


def load_scene(path: str | Path) -> Scene:
    """A YAML scene file (docs/scene.schema.json), or an example's name (``"throw"``)."""
    _of_type("path", path, (str, Path), "a YAML scene file (str or Path) or an example's name")
    return scenefile.load_scene(path)


def scene_from_arrays(
    pos,
    radius,
    *,
    vel=None,
    angvel=None,
    frames: int = 100,
    dt: float = 0.1,
    name: str = "arrays",
    **fields,
) -> Scene:
    """A scene from its start: pos ``[N, 3]``, radius ``[N]`` (or one number), ``frames`` to
    simulate at interval ``dt``; ``vel``, ``angvel`` ``[N, 3]`` (default zero); ``fields``:
    quat ``[N, 4]``, and mass, materials, planes, effects as in
    :meth:`Trajectory.from_arrays`. Its values are checked as a scene file's are (placement,
    materials' coefficients, orientations: :func:`physgnn.groundtruth.scene_values.arrays`)."""
    frames = FRAMES.check("frames", frames, error=ArgumentError)
    _positions(pos)
    start = {k: [v] if k == "quat" else v for k, v in fields.items()}
    velocities = tuple(None if v is None else [v] for v in (vel, angvel))
    first = Trajectory.from_arrays([pos], radius, dt, velocities=velocities, name=name, **start)
    scene = dataclasses.replace(scene_of(first), n_frames=frames).validate()
    scenefile.check_placement(f"scene '{name}'", scene.pos, scene.radius, scene.planes)
    return scene_values.arrays(f"scene '{name}'", scene)  # materials, orientations


def _positions(pos) -> None:
    """``pos`` is ``[N, 3]`` numbers; else one line naming it."""
    try:
        shape = np.shape(np.asarray(pos, np.float64))
    except (TypeError, ValueError):  # "abc", ragged rows
        shape = None
    if shape is None or len(shape) != 2 or shape[1] != 3:
        got = f"{pos!r:.40}" if shape is None else f"shape {list(shape)}"
        raise ArgumentError(f"pos must be an array [N, 3] of numbers (metres), got {got}")


def scene_of(traj: Trajectory) -> Scene:
    """The scene a trajectory starts from (its frame 0, its length, its planes' materials):
    :func:`~physgnn.physics.trajectory.scene_at` of frame 0."""
    return scene_at(traj, 0)


def simulate(scene: Scene, frames: int | None = None) -> Trajectory:
    """pybullet's trajectory of ``scene`` (``frames`` instead of its own length)."""
    _of_type("scene", scene, Scene, "a Scene: load_scene('throw'), scene_from_arrays(...)")
    if frames is not None:
        frames = FRAMES.check("frames", frames, error=ArgumentError)
        scene = dataclasses.replace(scene, n_frames=frames)
    return engine_simulate(scene)


def roll_out(
    model: Model, truth: Trajectory, constraints: int = 0, threads: int | None = 1
) -> Trajectory:
    """The model's rollout of ``truth`` from its first H+1 frames (its finite prefix if it
    diverged: ``diverged_at``); with ``constraints`` > 0, each learned step is followed by that
    many iterations of the constraint stage; on ``threads`` torch threads (None: the
    process's; 1, as ``simulate``: on a 2-core machine a second made rollouts slower). Warns
    (:class:`OutOfDistributionWarning`) when ``truth`` starts outside the model's training
    ranges."""
    _of_type("model", model, Model, "a Model: load_model('pretrained') or load_model(run_dir)")
    _of_type("truth", truth, Trajectory, "a Trajectory: simulate(scene) gives a scene's truth")
    constraints = CONSTRAINTS.check("constraints", constraints, error=ArgumentError)
    threads = THREADS.check("threads", threads, error=ArgumentError)
    found = outside(scene_of(truth), model.cfg)
    if found:
        warnings.warn(warning_text(truth.name, found), OutOfDistributionWarning, stacklevel=2)
    simulator = model.simulator
    if constraints > 0:
        simulator = ConstrainedSimulator(simulator, constraints)
    with torch_threads(threads):
        return rollout(simulator, [truth])[0]


def score(pred: Trajectory | None, truth: Trajectory, tol: float = 0.0) -> dict:
    """The metrics of ``pred`` against ``truth`` (``make eval``'s columns; None for a rollout
    that diverged, then ``diverged_at``), or the truth's own physics when ``pred`` is None.
    ``tol``: the penetration tolerance, a fraction of the diameter."""
    _of_type("pred", pred, (Trajectory, type(None)), "a Trajectory (roll_out's) or None")
    _of_type("truth", truth, Trajectory, "a Trajectory: simulate(scene) gives a scene's truth")
    _same_scene(pred, truth, "score")
    return scene_metrics(truth, pred, check_tolerance(tol, ArgumentError))


def _same_scene(pred: Trajectory | None, truth: Trajectory, verb: str) -> None:
    """``pred`` (None: none) has ``truth``'s spheres; else one line telling to ``verb`` a
    prediction of ``truth``'s own scene."""
    if pred is not None and pred.n_spheres != truth.n_spheres:
        raise ArgumentError(
            f"pred has {pred.n_spheres} spheres, truth {truth.n_spheres}: {verb} a prediction "
            "of truth's own scene (roll_out(model, truth))"
        )


def animate(
    truth: Trajectory,
    pred: Trajectory | None = None,
    stem: str | Path = "video",
    max_frames: int = 80,
    *,
    overwrite: bool = False,
) -> dict:
    """The shaded 3-D film of ``truth`` (left) beside ``pred`` (right; the truth again without
    one): ``stem.gif``, ``stem.mp4`` and ``stem_frame.png``; returns their paths by kind. An
    existing file of those names is refused (:class:`FileExistsError`, nothing written)
    unless ``overwrite=True``."""
    _of_type("truth", truth, Trajectory, "a Trajectory: simulate(scene) gives a scene's truth")
    _of_type("pred", pred, (Trajectory, type(None)), "a Trajectory (roll_out's) or None")
    _of_type("stem", stem, (str, Path), "a path without suffix (str or Path), e.g. 'film'")
    film = whole(2, what="frames of the film", example=80)
    max_frames = film.check("max_frames", max_frames, error=ArgumentError)
    _of_type("overwrite", overwrite, bool, "True or False")
    _same_scene(pred, truth, "animate")
    there = [f"{stem}{end}" for end in FILM if Path(f"{stem}{end}").exists()]
    if there and not overwrite:
        more = f" (and {len(there) - 1} more)" if len(there) > 1 else ""
        raise FileExistsError(
            f"animate: {there[0]}{more} is there already: choose another stem, or pass "
            "overwrite=True to replace it"
        )
    panel = (truth, "ground truth") if pred is None else (pred, "prediction")
    return render_side_by_side(stem, truth, [panel], title=truth.name, max_frames=max_frames)


def export(trajs: Trajectory | list[Trajectory], folder: str | Path, format: str = "vtk") -> Path:
    """Write ``trajs`` into ``folder`` as ``format``: ``vtk`` (one trajectory: ParaView files,
    returns the series file), ``gns`` or ``lagrangebench`` (a ``test`` split and metadata.json;
    ``{"train": [...], "valid": [...], "test": [...]}`` writes those splits, the files the
    peers' trainers open), ``hdf5`` (physgnn's dataset schema, ``trajectories.h5``). The folder
    is written whole, replacing an earlier export there; a folder holding other files is
    refused (:mod:`physgnn.data.exports`). What each format cannot hold: docs/DATA.md."""
    _of_type("folder", folder, (str, Path), "a folder's path (str or Path), e.g. 'out'")
    if format not in FORMATS:
        raise SceneError(f"export format '{format}' is unknown; choose one of {list(FORMATS)}")
    splits = (dict(trajs) or {"test": []}) if isinstance(trajs, dict) else {"test": trajs}
    if isinstance(trajs, dict) and format not in ("gns", "lagrangebench"):
        raise ArgumentError(f"trajs: splits (a dict) are for gns and lagrangebench, not {format}")
    for split, items in splits.items():
        name = f"trajs[{split!r}]" if isinstance(trajs, dict) else "trajs"
        listed = hasattr(items, "__iter__") and not isinstance(items, str)
        if not (isinstance(items, Trajectory) or listed):
            raise ArgumentError(
                f"{name} must be a Trajectory or a list of them (e.g. [truth, pred]), "
                f"got {type(items).__name__}"
            )
        splits[split] = [items] if isinstance(items, Trajectory) else list(items)
    trajs = splits.get("test", [])
    if format == "vtk" and len(trajs) > 1:
        raise SceneError(f"export to vtk takes one trajectory, got {len(trajs)}: one folder each")
    for items in splits.values():
        exports.check_exportable(items, f"export to {format}")
    if format == "vtk":
        return vtk.write_vtk(trajs[0], folder)
    if format == "gns":
        return interchange.write_gns(folder, splits)
    if format == "lagrangebench":
        return interchange.write_lagrangebench(folder, splits)
    return hdf5_export.write_hdf5(folder, trajs)
