"""The rollouts of an evaluation and what is measured of them: metrics.csv rows, OOD energy
series, the filmed run's OOD rollouts, the stability rows (OOD and hard scenes) and OOD (c)
again with sleeping spheres. Truth and rollouts alike are
:class:`~physgnn.physics.trajectory.Trajectory` objects."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from omegaconf import DictConfig, OmegaConf
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn import metrics
from physgnn.errors import ConfigError
from physgnn.evaluation import stability
from physgnn.evaluation.runs import SPLITS, RunInfo
from physgnn.groundtruth.hard import hard_split
from physgnn.models.capture import is_compiled
from physgnn.models.settings import ALLOWED, torch_threads
from physgnn.physics.trajectory import Trajectory
from physgnn.report.table import COLUMNS, SLEEP_SCENE, SLEEP_SUFFIX
from physgnn.rollout import rollout


def sleep_settings(cfg: DictConfig) -> dict:
    """The :class:`physgnn.models.sleeping.SleepingSimulator` settings of ``cfg.rollout.sleep``
    (``{}``: its defaults)."""
    r = cfg.get("rollout") or {}
    return OmegaConf.to_container(r["sleep"]) if r.get("sleep") is not None else {}


def rollout_settings(cfg: DictConfig) -> dict:
    """``rollout`` keyword arguments from ``cfg.rollout``: ``sleep``, the sleep settings when
    ``sleeping`` is on, else False."""
    r = cfg.get("rollout") or {}
    return {"sleep": sleep_settings(cfg) if r.get("sleeping", False) else False}


def rollout_threads(cfg: DictConfig) -> int | None:
    """``cfg.rollout.threads``: the torch threads of every learned rollout (None: the
    process's). Refused in one line naming the key: not a whole number from 1, nor null."""
    r = cfg.get("rollout") or {}
    return ALLOWED["threads"].check("rollout.threads", r.get("threads"), error=ConfigError)


def predict(job: RunInfo, traj: Trajectory, settings: dict | None = None) -> Trajectory:
    """For the ground truth, ``traj`` itself; else the job's rollout of it (finite prefix, the
    model's own velocities). Every scorer measures energy from finite-difference velocities
    (:func:`metrics_row`): with the engine's, the truth's energy gain would be lower than an
    FD rollout's could be."""
    if job.simulator is None:
        return traj
    return rollout(job.simulator, [traj], **(settings or {}))[0]


def metrics_row(
    info: RunInfo,
    split: str,
    traj: Trajectory,
    pred: Trajectory,
    tol: float,
    threads: int | None = None,
) -> dict:
    """One metrics.csv row (columns of :data:`physgnn.report.table.COLUMNS`); ``threads``: the
    cores the rollout ran on (a learned rollout's torch threads, pybullet's processes; None: not
    timed against another)."""
    m = metrics.trajectory_metrics(pred.with_finite_velocities(), traj, tol=tol, horizon=20)
    row = {k: m.get(k) for k in COLUMNS}
    row.update(
        run=info.name,
        experiment=info.experiment,
        overrides=info.overrides,
        seed=info.seed,
        split=split,
        trajectory=traj.name,
        n_spheres=traj.n_spheres,
        n_frames=pred.n_frames,
        diverged_at=pred.diverged_at,
        fps=pred.fps,
        threads=threads,
    )
    return row


def energy_of(traj: Trajectory, pred: Trajectory) -> np.ndarray:
    """``[T]``: the energy of ``pred`` from finite-difference velocities, as every row's."""
    vel = pred.with_finite_velocities().vel
    return metrics.energy_series(pred.pos, vel, traj.mass, traj.radius)


def warm_up(job: RunInfo, splits: dict[str, list[Trajectory]], batch_scenes: bool = True):
    """Untimed rollouts before the timed ones, so that one-off costs do not land in the FPS:
    one short rollout (lazy imports, allocator, first kernels); for a compiled step every
    group of every split as it will be timed (``batch_scenes``), whose compiles of the shapes
    it meets (dynamo specialises sizes 0 and 1, and a frame's number of passes) took a
    compiled eval's test rollouts from 2 000 down to 19 scene-frames/s."""
    sim = job.simulator
    first = next((t for s in SPLITS for t in splits[s]), None)
    if sim is None or first is None:
        return
    if not is_compiled(sim):
        rollout(sim, [first.truncated(int(sim.H) + 3)])
        return
    for split in SPLITS:
        for group in _groups(splits[split], batch_scenes):
            rollout(sim, group)


def _groups(trajs: list[Trajectory], batch_scenes: bool) -> list[list[Trajectory]]:
    """The rollout calls of a split: all its scenes in one (``batch_scenes``), else one each."""
    return [trajs] if batch_scenes else [[t] for t in trajs]


@dataclass
class Collected:
    """What the rollouts of an evaluation leave: metrics rows, OOD energy series
    (``{scene: {label: E [T]}}``: the ground truth and the runs named in ``keep``), the OOD
    rollouts of the filmed runs ``film`` (``{scene: (truth, [(rollout, run name), ...])}``, in
    the order the runs were rolled out), with ``stab`` a list, the
    stability rows of the ground truth's and the learned runs' OOD rollouts and, with ``saved``
    a dict, every learned run's rollouts (``{(run name, split): [rollout, ...]}``)."""

    keep: set[str]
    film: list[RunInfo]
    tol: float
    stab: list | None = None
    rest_tol: float = 0.01
    rows: list[dict] = field(default_factory=list)
    energies: dict = field(default_factory=dict)
    films: dict = field(default_factory=dict)
    saved: dict | None = None

    def add(
        self,
        job: RunInfo,
        split: str,
        traj: Trajectory,
        pred: Trajectory,
        threads: int | None = None,
    ) -> None:
        self.rows.append(metrics_row(job, split, traj, pred, self.tol, threads))
        if self.saved is not None and job.run_dir is not None:
            self.saved.setdefault((job.name, split), []).append(pred)
        if split != "ood":
            return
        truth = job.simulator is None
        if truth or job.name in self.keep:
            label = "ground truth" if job.name == "ground_truth" else job.name
            self.energies.setdefault(traj.name, {})[label] = energy_of(traj, pred)
        if any(job is filmed for filmed in self.film):
            self.films.setdefault(traj.name, (traj, []))[1].append((pred, job.name))
        if self.stab is not None and (truth or job.run_dir is not None):
            self.stab.append(stability_row(job, traj, pred, self.rest_tol))


def predict_split(job: RunInfo, trajs: list[Trajectory], settings: dict | None = None):
    """:func:`predict` of every trajectory of a split in one rollout call (the scenes batched in
    one graph per frame). Differs from one-by-one rollouts by float rounding only, and is
    deterministic. Each rollout's ``fps`` is the batch's scene-frames per second (the frames
    every scene produced over the call's time): a frame of one scene costs ``1 / fps``."""
    if job.simulator is None or not trajs:
        return [predict(job, t, settings) for t in trajs]
    preds = rollout(job.simulator, trajs, **(settings or {}))
    produced = [p.n_frames - p.start - 1 for p in preds]
    steps = max(produced)
    scale = sum(produced) / steps if steps > 0 else 1.0
    return [dataclasses.replace(p, fps=p.fps * scale) for p in preds]


def roll_all(
    jobs: list[RunInfo],
    data: dict,
    out: Collected,
    settings: dict | None = None,
    batch_scenes: bool = True,
    threads: int | None = None,
):
    """Every job on every test and OOD trajectory of its dataset, with a progress bar; what is
    measured goes to ``out``. ``settings``: keyword arguments of every rollout;
    ``batch_scenes``: a split's scenes in one rollout call (:func:`predict_split`), else one
    rollout per trajectory; ``threads``: torch threads of every job (None: the process's;
    the rows of those that roll out in torch, the learned runs, static and gravity_only, say
    how many)."""
    total = sum(len(data[j.dataset][s]) for j in jobs for s in SPLITS)
    with progress() as bar:
        task = bar.add_task("evaluating", total=total)
        for job in jobs:
            with torch_threads(threads) as ran_on:
                _roll_job(job, data, out, settings, batch_scenes, bar, task, ran_on)
    return out


def _roll_job(job: RunInfo, data: dict, out: Collected, settings, batch_scenes, bar, task, ran_on):
    """One job of :func:`roll_all` on every test and OOD trajectory of its dataset, on
    ``ran_on`` torch threads (its rows say so where the job rolls out in torch)."""
    warm_up(job, data[job.dataset], batch_scenes)
    threads = ran_on if job.simulator is not None else None
    for split in SPLITS:
        for group in _groups(data[job.dataset][split], batch_scenes):
            names = group[0].name if len(group) == 1 else f"{split} ({len(group)} scenes)"
            bar.update(task, description=f"{job.name} · {names}")
            for traj, pred in zip(group, predict_split(job, group, settings), strict=True):
                out.add(job, split, traj, pred, threads)
            bar.advance(task, len(group))


def rest_tol(cfg: DictConfig) -> float:
    return float(OmegaConf.select(cfg, "hard.rest_tol", default=0.01))


def stability_row(job: RunInfo, traj: Trajectory, pred: Trajectory, tol: float) -> dict:
    """The stability numbers of one OOD rollout (the ground truth: its own row)."""
    if job.simulator is None:
        return stability.truth_row(traj, "ood", tol) | {"run": job.name}
    m = stability.measure(traj, pred, tol)
    return {"run": job.name, "experiment": job.experiment, "source": "ood", **m}


def hard_rows(runs: list[RunInfo], cfg: DictConfig) -> list[dict]:
    """The ground truth and every learned run on the hard scenes of ``cfg.hard`` (simulated
    once, cached in ``cfg.hard.dir``; cut to ``cfg.max_frames``)."""
    hard = cfg.hard
    trajs = hard_split(hard.dir, hard.scenes, hard.engine, hard.seed)
    trajs = [t.truncated(cfg.max_frames) for t in trajs]
    rows = [stability.truth_row(t, "hard", hard.rest_tol) for t in trajs]
    settings = rollout_settings(cfg)
    with progress() as bar:
        task = bar.add_task("stability", total=len(runs))
        for run in runs:
            bar.update(task, description=f"stability · {run.name}")
            rows += stability.rollout_rows(
                run.name, run.experiment, run.simulator, trajs, "hard", hard.rest_tol, **settings
            )
            bar.advance(task)
    return rows


def sleeping_rows(
    film: RunInfo,
    ood: list[Trajectory],
    tol: float,
    sleep: dict | None = None,
    threads: int | None = None,
) -> list[dict]:
    """OOD (c) rolled out again with sleeping spheres (settings ``sleep``) on ``threads``
    torch threads (None: the process's), as the run ``<name>+sleeping``."""
    info = dataclasses.replace(
        film,
        name=film.name + SLEEP_SUFFIX,
        overrides=(film.overrides + " rollout.sleeping=true").strip(),
    )
    settings = {"sleep": sleep if sleep is not None else True}
    with torch_threads(threads) as ran_on:
        return [
            metrics_row(info, "ood", traj, predict(film, traj, settings), tol, ran_on)
            for traj in ood
            if traj.name == SLEEP_SCENE
        ]


def progress() -> Progress:
    return Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn()
    )
