"""Evaluate finished runs: ``make eval`` (:func:`evaluate`).

Evaluates every finished run under ``${paths.outputs}`` (``runs/`` and ``multirun/``), one run
folder or one multirun folder, together with the references ``ground_truth`` (the data
itself), ``static`` and ``gravity_only`` on each dataset the runs were trained on. Every test
and OOD trajectory is rolled out from its first H+1 frames; a diverged rollout's metrics are
on its finite prefix and carry ``diverged_at``. With ``stability=true`` (default) every learned
run is also rolled out on the hard scenes of ``hard`` and measured with
:mod:`physgnn.evaluation.stability` (``stability.csv`` and the report's stability section).
Every learned run also falls freely from ``freefall.heights`` (:mod:`physgnn.evaluation.freefall`,
``freefall.csv``) and bounces once per training material (:mod:`physgnn.evaluation.bounce`,
``bounce.csv``). Writes metrics.csv, report.md, figures and videos into ``report_dir``; with
``rerun=true`` also ``videos/<ood scene>.rrd``, the filmed run's rollouts as Rerun recordings.
A ``report_dir`` holding files physgnn did not write is refused unless ``overwrite=true``
(:func:`physgnn.files.claim_folder`); an eval that fails before it writes leaves no folder it
made (:func:`physgnn.files.claimed`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path, PurePosixPath

from omegaconf import DictConfig, OmegaConf

from physgnn.data.dataset import write_split
from physgnn.evaluation import learned_settings, onestep, rerun_log, same_work, turns
from physgnn.evaluation.bounce import bounce_rows
from physgnn.evaluation.bounce import check_settings as bounce_settings
from physgnn.evaluation.eval_checks import check_eval_values, check_seed_frames
from physgnn.evaluation.freefall import check_settings as freefall_settings
from physgnn.evaluation.freefall import freefall_rows
from physgnn.evaluation.invariance import invariance_rows
from physgnn.evaluation.rollouts import (
    Collected,
    hard_rows,
    rest_tol,
    roll_all,
    rollout_settings,
    rollout_threads,
    sleep_settings,
    sleeping_rows,
)
from physgnn.evaluation.runs import (
    EvalError,
    RunInfo,
    constrained_variants,
    load_datasets,
    load_runs,
    load_splits,
    pick_video_run,
    references,
)
from physgnn.evaluation.video3d import render_side_by_side
from physgnn.files import claimed_outputs
from physgnn.report import bounce, figures, freefall, invariance, stability, table
from physgnn.report import onestep as onestep_report
from physgnn.report.document import write_report
from physgnn.rollout import VELOCITY

# What an eval writes into its report_dir (replaced whole by the next eval).
REPORT_OUTPUTS = (
    "report.md",
    "metrics.csv",
    "onestep.csv",
    "stability.csv",
    "freefall.csv",
    "bounce.csv",
    "invariance.csv",
    "figures",
    "videos",
    "rollouts",
)


def evaluate(cfg: DictConfig) -> Path:
    """Evaluate the runs named by ``cfg`` and write ``cfg.report_dir``; returns report.md.

    One eval at a time per ``report_dir`` (a second is refused in one line); everything is
    written into its own staging folder first and moved into ``report_dir`` at the end,
    replacing the previous eval's outputs (:data:`REPORT_OUTPUTS`) whole: a report folder
    always holds one eval, and an interrupted eval leaves the last one as it was
    (:func:`physgnn.files.staged_outputs`)."""
    check_eval_values(cfg)
    report_dir = Path(cfg.report_dir)
    if cfg.get("rerun"):
        rerun_log.require()  # before the rollouts, not after them
    ours = report_dir == Path(cfg.paths.report_dir)
    overwrite = bool(cfg.get("overwrite"))
    with claimed_outputs(report_dir, "report_dir", REPORT_OUTPUTS, overwrite, ours) as staging:
        _evaluate_into(cfg, staging)
    return report_dir / "report.md"


def _evaluate_into(cfg: DictConfig, report_dir: Path) -> Path:
    """The eval itself, written into ``report_dir`` (the staging folder)."""
    outputs = Path(cfg.paths.outputs)
    runs, skipped = load_runs(cfg, outputs)
    runs += constrained_variants(runs, int(OmegaConf.select(cfg, "rollout.constraints") or 0))
    if not runs and not cfg.dataset:
        raise EvalError(f"no finished run under {outputs} (make train first, or pass dataset=PATH)")
    if cfg.dataset:
        data = {Path(cfg.dataset): load_splits(Path(cfg.dataset), cfg.max_frames)}
    else:
        data, runs = load_datasets(runs, cfg.max_frames, skipped)
    check_seed_frames(cfg, runs)
    jobs = [ref for d in data for ref in references(d, len(data) > 1)] + runs
    film = pick_video_run(runs, cfg.video_run)
    keep = {r.name for r in runs[: cfg.energy_runs]} | ({film.name} if film else set())
    stab = [] if cfg.get("stability") else None
    settings = rollout_settings(cfg)
    filmed = [r for r in runs if film and r.name in (film.name, f"{film.name} + constraints")]
    batched = bool(OmegaConf.select(cfg, "rollout.batch_scenes", default=True))
    collected = Collected(keep, filmed, cfg.tol, stab, rest_tol(cfg))
    collected.saved = {} if cfg.get("save_rollouts") else None
    threads = rollout_threads(cfg)
    out = roll_all(jobs, data, collected, settings, batched, threads)
    rows, setting_jobs = learned_settings.eval_rows(cfg, runs, data, settings, batched)
    out.rows += rows + engine_rows(cfg, runs, data, batched)
    if batched:
        out.rows = in_turns(cfg, runs + setting_jobs, data, settings, out.rows)
    if out.saved:
        write_rollouts(report_dir / "rollouts", out.saved)
    if film is not None and cfg.sleeping_compare and settings["sleep"] is False:
        ood = data[film.dataset]["ood"]
        out.rows += sleeping_rows(film, ood, cfg.tol, sleep_settings(cfg), threads)
    table.write_csv(report_dir / "metrics.csv", out.rows)
    onestep_report.write_csv(report_dir / "onestep.csv", onestep_rows(cfg, runs, data))
    if stab is not None:
        stability.write_csv(report_dir / "stability.csv", stab + hard_rows(runs, cfg))
    else:
        (report_dir / "stability.csv").unlink(missing_ok=True)  # no stale section
    freefall.write_csv(report_dir / "freefall.csv", _freefall(runs, cfg.get("freefall"), settings))
    bounce.write_csv(report_dir / "bounce.csv", _bounce(runs, cfg.get("bounce"), settings))
    invariance.write_csv(report_dir / "invariance.csv", _invariance(runs, cfg, settings))
    if out.energies:
        dts = {name: _dt(data, name) for name in out.energies}
        figures.plot_energy(report_dir / "figures" / "energy_ood.png", out.energies, dts)
    if cfg.videos and film is not None:
        write_videos(report_dir / "videos", out.films, cfg.video_frames)
    if cfg.get("rerun"):
        for scene, (traj, panels) in sorted(out.films.items()):
            rerun_log.log_rerun(report_dir / "videos" / f"{scene}.rrd", traj, panels[0][0])
    return write_report(report_dir, out.rows, skipped=skipped)


def engine_rows(cfg: DictConfig, runs: list[RunInfo], data: dict, batched: bool) -> list[dict]:
    """pybullet at ``cfg.pybullet.substeps`` on the learned runs' own work
    (:mod:`physgnn.evaluation.same_work`), timed as the learned rollouts are: with
    ``batched``, each split's scenes at once in ``cfg.pybullet.processes`` processes (the
    split's rate), else one scene at a time here (each its own). None without a ``pybullet``
    config."""
    settings = same_work.check_settings(cfg.get("pybullet"))
    if settings is None:
        return []
    substeps, processes = settings
    jobs = same_work.engine_jobs(runs, len(data) > 1)
    return same_work.engine_rows(jobs, data, substeps, processes if batched else None, cfg.tol)


def in_turns(
    cfg: DictConfig, learned: list[RunInfo], data: dict, settings: dict, rows: list[dict]
) -> list[dict]:
    """``rows`` with the learned and pybullet frames/s taken again in ``pybullet.turns``
    rounds (:mod:`physgnn.evaluation.turns`); as they are without a ``pybullet`` config or
    with ``turns: 0``. ``learned``: the runs and setting jobs (a setting's own threads)."""
    engine = same_work.check_settings(cfg.get("pybullet"))
    rounds = turns.check_turns(cfg.get("pybullet"))
    if engine is None or not rounds:
        return rows
    threads = rollout_threads(cfg)
    timed = [
        (job, job.extra.get("knobs", {}).get("threads", threads))
        for job in learned
        if job.simulator is not None
    ]
    engines = same_work.engine_jobs(learned, len(data) > 1)
    fps = turns.timed_in_turns(timed, engines, data, (*engine, rounds), settings)
    return turns.retimed(rows, fps)


def onestep_rows(cfg: DictConfig, runs: list[RunInfo], data: dict) -> list[dict]:
    """The one-step error by regime of every learned run and of pybullet at
    ``cfg.pybullet.substeps`` (none without a ``pybullet`` config) on ``cfg.onestep.splits``
    (:mod:`physgnn.evaluation.onestep`); none with ``onestep: null``."""
    settings = onestep.check_settings(cfg.get("onestep"))
    if settings is None:
        return []
    engine = same_work.check_settings(cfg.get("pybullet"))
    substeps = engine[0] if engine is not None else []
    return onestep.onestep_rows(runs, data, settings, substeps, len(data) > 1)


def _freefall(runs: list[RunInfo], cfg: DictConfig | None, settings: dict) -> list[dict]:
    """Every learned run dropped from ``cfg.heights`` (:mod:`physgnn.evaluation.freefall`);
    none without a ``freefall`` config."""
    args = freefall_settings(cfg)
    if args is None:
        return []
    rows = []
    for run in runs:
        rows += freefall_rows(run.name, run.simulator, *args, **settings)
    return rows


def _bounce(runs: list[RunInfo], cfg: DictConfig | None, settings: dict) -> list[dict]:
    """Every learned run bouncing with each of ``cfg.materials``
    (:mod:`physgnn.evaluation.bounce`); none without a ``bounce`` config."""
    args = bounce_settings(cfg)
    if args is None:
        return []
    rows = []
    for run in runs:
        rows += bounce_rows(run.name, run.simulator, *args, **settings)
    return rows


def _invariance(runs: list[RunInfo], cfg: DictConfig, settings: dict) -> list[dict]:
    """Every learned run's invariance checks (:mod:`physgnn.evaluation.invariance`); none
    with ``invariance: null``."""
    checks = cfg.get("invariance")
    if checks is None:
        return []
    return [
        r for run in runs for r in invariance_rows(run.name, run.simulator, **checks, **settings)
    ]


def _dt(data: dict, scene: str) -> float:
    for splits in data.values():
        for traj in splits["ood"]:
            if traj.name == scene:
                return float(traj.dt)
    return 1.0


def write_videos(video_dir: Path, films: dict, max_frames: int) -> list[Path]:
    """Per OOD scene ``<scene>.gif``, ``.mp4`` and ``_frame.png``: the shaded 3-D view of the
    ground truth beside the filmed runs' rollouts (the pure run, then its constrained variant
    when the eval has one); returns the GIFs."""
    paths = []
    for scene, (traj, panels) in sorted(films.items()):
        labelled = [(pred, f"prediction\n{name}") for pred, name in panels]
        stem = video_dir / scene
        render_side_by_side(stem, traj, labelled, title=scene, max_frames=max_frames)
        paths.append(stem.with_name(f"{scene}.gif"))
    return paths


def write_rollouts(folder: Path, saved: dict) -> list[Path]:
    """``<folder>/<run name>/<split>.h5`` per learned run and split: its rollouts in the dataset
    schema (groups named as the truth's), with what made them in each group's attributes.
    Always under ``folder``: the name of a run outside ``paths.outputs`` (its path) is taken
    without its root, never as the run's own folder."""
    paths = []
    for (name, split), preds in sorted(saved.items()):
        trajs = [dataclasses.replace(p, attrs=p.attrs | made_by(p, name)) for p in preds]
        parts = PurePosixPath(name.replace(" ", "")).parts
        path = folder.joinpath(*[p for p in parts if p not in ("/", ".", "..")], f"{split}.h5")
        paths.append(write_split(path, trajs, {"split": split, "preset": f"rollouts of {name}"}))
    return paths


def made_by(pred, run: str) -> dict:
    """A saved rollout's attributes: the run, its first predicted frame - 1 (``start``), where
    it diverged (-1: it did not) and how its velocities were obtained."""
    diverged = -1 if pred.diverged_at is None else int(pred.diverged_at)
    velocity = pred.attrs.get("velocity", VELOCITY[False])
    return {
        "made_by": "physgnn learned simulator",
        "run": run,
        "start": int(pred.start),
        "diverged_at": diverged,
        "velocity": velocity,
    }
