"""``python -m physgnn.eval`` / ``make eval``: metrics.csv, report.md, figures and videos.

Evaluates every finished run under ``${paths.outputs}`` (``runs/`` and ``multirun/``), one run
folder or one multirun folder, together with the references ``ground_truth`` (the data
itself), ``static`` and ``gravity_only`` on each dataset the runs were trained on. Every test
and OOD trajectory is rolled out from its first H+1 frames; a diverged rollout's metrics are
on its finite prefix and carry ``diverged_at``. With ``stability=true`` (default) every learned
run is also rolled out on the hard scenes of ``hard`` and measured with
:mod:`physgnn.evaluation.stability` (``stability.csv`` and the report's stability section).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from omegaconf import DictConfig, OmegaConf
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from physgnn import metrics
from physgnn.data.dataset import DatasetError, read_split
from physgnn.errors import PhysgnnError
from physgnn.evaluation import stability
from physgnn.physics.scene import Trajectory
from physgnn.report import document as report
from physgnn.report import figures as plots
from physgnn.report import video
from physgnn.rollout import rollout
from physgnn.training import runs as training_runs

SPLITS = ("test", "ood")


class EvalError(PhysgnnError, RuntimeError):
    """Evaluation cannot start (one line naming the problem)."""


@dataclass
class RunInfo:
    """A finished training run (or a reference: ``ground_truth``, ``static``, ``gravity_only``)."""

    name: str
    experiment: str
    overrides: str = ""
    seed: int | None = None
    run_dir: Path | None = None
    dataset: Path | None = None
    simulator: object = None
    extra: dict = field(default_factory=dict)


# ---------------------------------------------------------------- run discovery


def run_status(run_dir: Path) -> str:
    """``status`` of a run's run.json (``"unreadable"`` when it cannot be read)."""
    try:
        return str(json.loads((run_dir / "run.json").read_text()).get("status"))
    except (OSError, ValueError):
        return "unreadable"


def all_runs(target: str | None, outputs: Path) -> list[Path]:
    """Every folder with a run.json: under ``outputs/{runs,multirun}`` (target None), the
    folder ``target`` itself, or below it (a multirun folder). Sorted."""
    if target is None:
        roots = [outputs / "runs", outputs / "multirun"]
    else:
        root = Path(target)
        if not root.is_dir():
            raise EvalError(f"run folder {target} does not exist")
        if (root / "run.json").exists():
            return [root]
        roots = [root]
    return sorted({p.parent for r in roots if r.is_dir() for p in r.rglob("run.json")})


def find_runs(target: str | None, outputs: Path) -> list[Path]:
    """The finished runs of :func:`all_runs`; a named target without one is an error."""
    runs = [p for p in all_runs(target, outputs) if run_status(p) == "finished"]
    if target is not None and not runs:
        if (Path(target) / "run.json").exists():
            status = run_status(Path(target))
            raise EvalError(f"run {target} has not finished (run.json status is '{status}')")
        raise EvalError(f"no finished run (run.json with status 'finished') under {target}")
    return runs


def run_name(run_dir: Path, outputs: Path) -> str:
    try:
        return run_dir.resolve().relative_to(outputs.resolve()).as_posix()
    except ValueError:
        return run_dir.as_posix()


def run_info(run_dir: Path, outputs: Path) -> RunInfo:
    """Experiment, overrides (space-joined) and seed from ``run.json``."""
    info = json.loads((run_dir / "run.json").read_text())
    overrides = info.get("overrides")
    if overrides is None and (run_dir / ".hydra" / "overrides.yaml").exists():
        overrides = yaml.safe_load((run_dir / ".hydra" / "overrides.yaml").read_text())
    if isinstance(overrides, list | tuple):
        overrides = " ".join(str(o) for o in overrides)
    return RunInfo(
        name=run_name(run_dir, outputs),
        experiment=str(info.get("experiment")),
        overrides=overrides or "",
        seed=info.get("seed"),
        run_dir=run_dir,
    )


def dataset_of(run_cfg) -> Path:
    """The dataset folder a run was trained on (``datamodule.data_dir`` or ``data.dir``)."""
    for key in ("datamodule.data_dir", "data.dir"):
        try:
            value = OmegaConf.select(run_cfg, key, throw_on_missing=False)
        except Exception:  # an interpolation that only resolves inside Hydra
            value = None
        if value:
            return Path(str(value))
    raise EvalError("the run's config names no dataset (datamodule.data_dir); pass dataset=PATH")


# ---------------------------------------------------------------- data


def truncate(traj: Trajectory, max_frames: int | None) -> Trajectory:
    if not max_frames or traj.n_frames <= max_frames:
        return traj
    cut = {k: getattr(traj, k)[:max_frames] for k in ("pos", "quat", "vel", "angvel")}
    return dataclasses.replace(traj, **cut)


def load_splits(data_dir: Path, max_frames: int | None) -> dict[str, list[Trajectory]]:
    """The test and OOD trajectories of a dataset folder, cut to ``max_frames``."""
    if not data_dir.is_dir():
        raise EvalError(f"dataset folder {data_dir} does not exist (make data first)")
    out = {}
    for split in SPLITS:
        path = data_dir / f"{split}.h5"
        out[split] = [truncate(t, max_frames) for t in read_split(path)] if path.exists() else []
    if not any(out.values()):
        raise EvalError(f"dataset folder {data_dir} has neither test.h5 nor ood.h5")
    return out


# ---------------------------------------------------------------- rollouts and rows


@dataclass
class Prediction:
    """One rollout's finite prefix: pos, vel ``[T', N, 3]``, quat ``[T', N, 4]``."""

    pos: np.ndarray
    vel: np.ndarray
    quat: np.ndarray | None
    start: int
    diverged_at: int | None
    fps: float | None

    def as_metrics_input(self) -> dict:
        """The ``pred`` argument of :func:`physgnn.metrics.trajectory_metrics`."""
        return dict(
            pos=self.pos,
            vel=self.vel,
            quat=self.quat,
            start=self.start,
            diverged_at=self.diverged_at,
        )


def truth_prediction(traj: Trajectory) -> Prediction:
    d = metrics.trajectory_dict(traj)
    return Prediction(d["pos"], d["vel"], d["quat"], 0, None, None)


def rollout_prediction(simulator, traj: Trajectory, **kwargs) -> Prediction:
    """Roll one trajectory out with ``simulator`` (``kwargs`` go to :func:`rollout`, e.g.
    ``sleeping=True``); the result keeps the finite prefix."""
    res = rollout(simulator, [traj], **kwargs)[0]
    f64 = lambda a: np.asarray(a, np.float64)  # noqa: E731
    return Prediction(
        f64(res.pos), f64(res.vel), f64(res.quat), int(res.start), res.diverged_at, float(res.fps)
    )


def metrics_row(info: RunInfo, split: str, traj: Trajectory, pred: Prediction, tol: float) -> dict:
    """One metrics.csv row (columns of ``report.COLUMNS``)."""
    m = metrics.trajectory_metrics(pred.as_metrics_input(), traj, tol=tol, horizon=20)
    row = {k: m.get(k) for k in report.COLUMNS}
    row.update(
        run=info.name,
        experiment=info.experiment,
        overrides=info.overrides,
        seed=info.seed,
        split=split,
        trajectory=traj.name,
        n_spheres=traj.n_spheres,
        n_frames=pred.pos.shape[0],
        diverged_at=pred.diverged_at,
        fps=pred.fps,
    )
    return row


def energy_of(traj: Trajectory, pred: Prediction) -> np.ndarray:
    return metrics.energy_series(pred.pos, pred.vel, traj.mass, traj.radius)


# ---------------------------------------------------------------- main


def references(dataset: Path, several: bool) -> list[RunInfo]:
    """ground_truth, static and gravity_only on one dataset (suffixed when there are several)."""
    from physgnn.models.baselines import GravityOnlySimulator, StaticSimulator

    suffix = f"[{dataset.name}]" if several else ""
    sims = {
        "ground_truth": None,
        "static": StaticSimulator(),
        "gravity_only": GravityOnlySimulator(),
    }
    return [
        RunInfo(
            name=k + suffix,
            experiment=k,
            overrides=f"dataset={dataset}",
            dataset=dataset,
            simulator=s,
        )
        for k, s in sims.items()
    ]


def load_runs(cfg: DictConfig, outputs: Path) -> tuple[list[RunInfo], list[str]]:
    """Every finished run with its simulator and dataset, and one note per run left out
    (not finished, or failing to load: one bad run must not stop the report of the others)."""
    run_dirs = find_runs(cfg.runs, outputs)
    skipped = [f"`{run_name(p, outputs)}`: status {run_status(p)}"
               for p in all_runs(cfg.runs, outputs) if p not in run_dirs]  # fmt: skip
    infos = []
    for run_dir in run_dirs:
        info = run_info(run_dir, outputs)
        try:
            info.simulator, run_cfg, _ = training_runs.load_run(run_dir)
            info.simulator.eval()
            info.dataset = Path(cfg.dataset) if cfg.dataset else dataset_of(run_cfg)
        except Exception as e:
            note = f"{type(e).__name__}: {e}".splitlines()[0]
            print(f"warning: skipping run {info.name}: {note}", file=sys.stderr)
            skipped.append(f"`{info.name}`: {note}")
            continue
        infos.append(info)
    return infos, skipped


def pick_video_run(runs: list[RunInfo], wanted: str | None) -> RunInfo | None:
    """The run whose OOD rollouts are filmed: ``wanted`` (a name), else the first baseline."""
    learned = [r for r in runs if r.run_dir is not None]
    if wanted:
        match = [r for r in learned if r.name == wanted or str(r.run_dir) == wanted]
        if not match:
            raise EvalError(f"video_run {wanted} is not among the evaluated runs")
        return match[0]
    order = sorted(
        learned,
        key=lambda r: (
            r.experiment != "baseline",
            report.config_label(r.overrides) != "default",
            r.seed if r.seed is not None else 0,
            r.name,
        ),
    )
    return order[0] if order else None


def load_datasets(runs: list[RunInfo], max_frames: int | None, skipped: list[str]):
    """The datasets of the runs; runs whose dataset cannot be read are left out with a note
    (an error when that leaves none). Returns ``({folder: splits}, runs kept)``."""
    data, errors = {}, {}
    for folder in dict.fromkeys(r.dataset for r in runs):
        try:
            data[folder] = load_splits(folder, max_frames)
        except (EvalError, DatasetError) as e:
            errors[folder] = str(e)
    if errors and not data:
        raise EvalError(next(iter(errors.values())))
    for r in runs:
        if r.dataset in errors:
            print(f"warning: skipping run {r.name}: {errors[r.dataset]}", file=sys.stderr)
            skipped.append(f"`{r.name}`: {errors[r.dataset]}")
    return data, [r for r in runs if r.dataset in data]


def evaluate(cfg: DictConfig) -> Path:
    """Evaluate the runs named by ``cfg`` and write ``cfg.report_dir``; returns report.md."""
    outputs, report_dir = Path(cfg.paths.outputs), Path(cfg.report_dir)
    runs, skipped = load_runs(cfg, outputs)
    if not runs and not cfg.dataset:
        raise EvalError(f"no finished run under {outputs} (make train first, or pass dataset=PATH)")
    if cfg.dataset:
        datasets = [Path(cfg.dataset)]
        data = {datasets[0]: load_splits(datasets[0], cfg.max_frames)}
    else:
        data, runs = load_datasets(runs, cfg.max_frames, skipped)
        datasets = list(data)
    jobs = [ref for d in datasets for ref in references(d, len(datasets) > 1)] + runs
    film = pick_video_run(runs, cfg.video_run)
    keep = {r.name for r in runs[: cfg.energy_runs]} | ({film.name} if film else set())
    stab = [] if cfg.get("stability") else None
    settings = rollout_settings(cfg)
    rows, energies, films = roll_all(
        jobs, data, keep, film, cfg.tol, stab, _rest_tol(cfg), settings
    )
    if film is not None and cfg.sleeping_compare and not settings["sleeping"]:
        rows += sleeping_rows(film, data[film.dataset]["ood"], cfg.tol, settings["sleep"])
    report.write_csv(report_dir / "metrics.csv", rows)
    if stab is not None:
        stability.write_csv(report_dir / "stability.csv", stab + hard_rows(runs, cfg))
    else:
        (report_dir / "stability.csv").unlink(missing_ok=True)  # no stale section
    if energies:
        dts = {name: _dt(data, name) for name in energies}
        plots.plot_energy(report_dir / "figures" / "energy_ood.png", energies, dts)
    if cfg.videos and film is not None:
        write_videos(report_dir / "videos", film, films, cfg.video_frames)
    bench_dir = cfg.paths.get("bench_dir")
    return report.write_report(report_dir, rows, bench_dir=bench_dir, skipped=skipped)


def warm_up(job: RunInfo, splits: dict[str, list[Trajectory]]) -> None:
    """One short untimed rollout, so that one-off costs (lazy imports, allocator, first
    kernels) do not land in the FPS of the first trajectory."""
    first = next((t for s in SPLITS for t in splits[s]), None)
    if job.simulator is not None and first is not None:
        rollout_prediction(job.simulator, truncate(first, int(job.simulator.H) + 3))


def roll_all(
    jobs: list[RunInfo],
    data: dict,
    keep: set[str],
    film: RunInfo | None,
    tol: float,
    stab: list | None = None,
    rest_tol: float = 0.01,
    settings: dict | None = None,
):
    """Every job on every test and OOD trajectory of its dataset, with a progress bar.

    Returns the metrics rows, the OOD energy series (``{scene: {label: E [T]}}``: the ground
    truth and the runs named in ``keep``) and the filmed run's OOD rollouts
    (``{scene: (trajectory, prediction)}``). With a list ``stab``, the stability rows of the
    ground truth's and the learned runs' OOD rollouts are appended to it. ``settings``:
    keyword arguments of every rollout (:func:`rollout_settings`).
    """
    rows, energies, films = [], {}, {}
    total = sum(len(data[j.dataset][s]) for j in jobs for s in SPLITS)
    with _progress() as bar:
        task = bar.add_task("evaluating", total=total)
        for job in jobs:
            warm_up(job, data[job.dataset])
            for split in SPLITS:
                for traj in data[job.dataset][split]:
                    bar.update(task, description=f"{job.name} · {traj.name}")
                    truth = job.simulator is None
                    pred = (
                        truth_prediction(traj)
                        if truth
                        else rollout_prediction(job.simulator, traj, **(settings or {}))
                    )
                    rows.append(metrics_row(job, split, traj, pred, tol))
                    if split == "ood" and (truth or job.name in keep):
                        label = "ground truth" if job.name == "ground_truth" else job.name
                        energies.setdefault(traj.name, {})[label] = energy_of(traj, pred)
                    if split == "ood" and job is film:
                        films[traj.name] = (traj, pred)
                    if split == "ood" and stab is not None and (truth or job.run_dir is not None):
                        stab.append(stability_row(job, traj, pred, rest_tol))
                    bar.advance(task)
    return rows, energies, films


def _rest_tol(cfg: DictConfig) -> float:
    return float(OmegaConf.select(cfg, "hard.rest_tol", default=0.01))


def stability_row(job: RunInfo, traj: Trajectory, pred: Prediction, rest_tol: float) -> dict:
    """The stability numbers of one OOD rollout (the ground truth: its own row)."""
    if job.simulator is None:
        return stability.truth_row(traj, "ood", rest_tol) | {"run": job.name}
    m = stability.measure(traj, pred.pos, pred.vel, pred.start, pred.diverged_at, rest_tol)
    return {"run": job.name, "experiment": job.experiment, "source": "ood", **m}


def hard_rows(runs: list[RunInfo], cfg: DictConfig) -> list[dict]:
    """The ground truth and every learned run on the hard scenes of ``cfg.hard`` (simulated
    once, cached in ``cfg.hard.dir``; cut to ``cfg.max_frames``)."""
    hard = cfg.hard
    trajs = stability.hard_split(hard.dir, hard.scenes, hard.engine, hard.seed)
    trajs = [truncate(t, cfg.max_frames) for t in trajs]
    rows = [stability.truth_row(t, "hard", hard.rest_tol) for t in trajs]
    with _progress() as bar:
        task = bar.add_task("stability", total=len(runs))
        for run in runs:
            bar.update(task, description=f"stability · {run.name}")
            rows += stability.rollout_rows(
                run.name,
                run.experiment,
                run.simulator,
                trajs,
                "hard",
                hard.rest_tol,
                **rollout_settings(cfg),
            )
            bar.advance(task)
    return rows


def _dt(data: dict, scene: str) -> float:
    for splits in data.values():
        for traj in splits["ood"]:
            if traj.name == scene:
                return float(traj.dt)
    return 1.0


def rollout_settings(cfg: DictConfig) -> dict:
    """``rollout`` keyword arguments from ``cfg.rollout``: ``sleeping`` (bool) and ``sleep``
    (the :class:`physgnn.models.sleeping.SleepingSimulator` settings)."""
    r = cfg.get("rollout") or {}
    sleep = OmegaConf.to_container(r["sleep"]) if r.get("sleep") is not None else {}
    return {"sleeping": bool(r.get("sleeping", False)), "sleep": sleep}


def sleeping_rows(
    film: RunInfo, ood: list[Trajectory], tol: float, sleep: dict | None = None
) -> list[dict]:
    """OOD (c) rolled out again with sleeping spheres (settings ``sleep``), as the run
    ``<name>+sleeping``."""
    info = dataclasses.replace(
        film,
        name=film.name + report.SLEEP_SUFFIX,
        overrides=(film.overrides + " rollout.sleeping=true").strip(),
    )
    rows = []
    for traj in ood:
        if traj.name == report.SLEEP_SCENE:
            pred = rollout_prediction(film.simulator, traj, sleeping=True, sleep=sleep)
            rows.append(metrics_row(info, "ood", traj, pred, tol))
    return rows


def write_videos(video_dir: Path, film: RunInfo, films: dict, max_frames: int) -> list[Path]:
    """One GIF per OOD scene: ground truth beside the filmed run's rollout."""
    paths = []
    for scene, (traj, pred) in sorted(films.items()):
        path = video_dir / f"{scene}.gif"
        video.render_gif(
            path,
            traj.pos,
            pred.pos,
            traj.radius,
            traj.planes,
            traj.plane_kind,
            title=f"{scene} · {film.name}",
            diverged_at=pred.diverged_at,
            max_frames=max_frames,
        )
        paths.append(path)
    return paths


def _progress() -> Progress:
    return Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn()
    )
