"""The runs an evaluation covers: finished training runs found under the outputs (each with its
simulator and dataset), the references ``ground_truth``, ``static`` and ``gravity_only``, and
the test and OOD trajectories of their datasets."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from omegaconf import DictConfig, OmegaConf

from physgnn.data.dataset import DatasetError, read_split
from physgnn.errors import ConfigError, PhysgnnError
from physgnn.models.baselines import GravityOnlySimulator, StaticSimulator
from physgnn.models.capture import compile_simulator
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.physics.trajectory import Trajectory
from physgnn.report.table import config_label
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


def all_runs(target: str | None, outputs: Path) -> list[Path]:
    """Every folder with a run.json: under ``outputs/{runs,multirun}`` (target None), the
    folder ``target`` itself, or below it (a multirun folder). Sorted."""
    if target is None:
        roots = [outputs / "runs", outputs / "multirun"]
    else:
        root = training_runs.resolve_run(target)
        if not root.is_dir():
            raise EvalError(f"run folder {target} does not exist: {GIVE_RUNS}")
        if (root / "run.json").exists():
            return [root]
        roots = [root]
    return sorted({p.parent for r in roots if r.is_dir() for p in r.rglob("run.json")})


def check_runs(runs) -> list[str | None]:
    """The targets ``runs`` names, each for :func:`all_runs`: ``[None]`` for null (every run
    under the outputs), else one folder (a run or a folder of runs) or each of a non-empty
    list of them. Anything else is refused in one line naming ``runs``."""
    if runs is None:
        return [None]
    targets = [runs] if isinstance(runs, str) else runs
    if isinstance(targets, Sequence) and targets and all(isinstance(t, str) and t for t in targets):
        return list(targets)
    given = OmegaConf.to_container(runs) if OmegaConf.is_config(runs) else runs
    raise ConfigError(
        "runs must be a run folder, a folder of runs or a non-empty list of them (null: every "
        f"finished run under paths.outputs), got {given!r} (e.g. runs=outputs/runs/default/seed0 "
        "or 'runs=[outputs/runs/default/seed0,outputs/runs/default/seed1]'; a folder named by "
        "a number: runs=./5)"
    )


# A truncated run (its step budget cut short by the time guard) is evaluated, and named so.
EVALUATED = training_runs.DONE
# The fix for a runs= that names no folder
GIVE_RUNS = (
    "give runs= a run folder or a folder of runs (outputs/runs/<experiment>/<time>, "
    f"outputs/multirun/<sweep>/<time>) or {training_runs.PRETRAINED}"
)


def find_runs(target: str | None, outputs: Path) -> list[Path]:
    """The finished (or truncated) runs of :func:`all_runs`; a named target without one is an
    error."""
    runs = [p for p in all_runs(target, outputs) if training_runs.run_status(p) in EVALUATED]
    if target is not None and not runs:
        folder = training_runs.resolve_run(target)
        if (folder / "run.json").exists():
            training_runs.check_done(folder, "evaluate it", EvalError)
        raise EvalError(f"no finished run (run.json with status 'finished') under {target}")
    return runs


def run_name(run_dir: Path, outputs: Path) -> str:
    if Path(run_dir).resolve() == training_runs.PRETRAINED_DIR.resolve():
        return training_runs.PRETRAINED
    try:
        return run_dir.resolve().relative_to(outputs.resolve()).as_posix()
    except ValueError:
        return run_dir.as_posix()


def run_info(run_dir: Path, outputs: Path) -> RunInfo:
    """Experiment, overrides (space-joined) and seed from ``run.json``."""
    info = training_runs.read_run_json(run_dir)
    overrides = info.get("overrides")
    if overrides is None and (run_dir / ".hydra" / "overrides.yaml").exists():
        overrides = yaml.safe_load((run_dir / ".hydra" / "overrides.yaml").read_text())
    if isinstance(overrides, list | tuple):
        overrides = " ".join(str(o) for o in overrides)
    name = run_name(run_dir, outputs)
    if info.get("status") == "truncated":
        name += " (truncated)"
    return RunInfo(
        name=name,
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


def load_splits(data_dir: Path, max_frames: int | None) -> dict[str, list[Trajectory]]:
    """The test and OOD trajectories of a dataset folder, cut to ``max_frames``."""
    if not data_dir.is_dir():
        raise EvalError(f"dataset folder {data_dir} does not exist (make data first)")
    out = {}
    for split in SPLITS:
        path = data_dir / f"{split}.h5"
        out[split] = [t.truncated(max_frames) for t in read_split(path)] if path.exists() else []
    if not any(out.values()):
        raise EvalError(f"dataset folder {data_dir} has neither test.h5 nor ood.h5")
    return out


def references(dataset: Path, several: bool) -> list[RunInfo]:
    """ground_truth, static and gravity_only on one dataset (suffixed when there are several)."""
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
    """Every finished run of ``cfg.runs`` (:func:`check_runs`) with its simulator and dataset,
    and one note per run left out (not finished, or failing to load: one bad run must not stop
    the report of the others)."""
    targets = check_runs(cfg.runs)
    run_dirs = _union(find_runs(t, outputs) for t in targets)
    found = _union(all_runs(t, outputs) for t in targets)
    skipped = [_not_evaluated(p, outputs) for p in found if p not in run_dirs]
    infos = []
    for run_dir in run_dirs:
        info = run_info(run_dir, outputs)
        try:
            info.simulator, run_cfg, _ = training_runs.load_run(run_dir)
            info.simulator.eval()
            if cfg.get("compile"):  # compiled by the warm-up rollout, before any timing
                compile_simulator(info.simulator, cache_dir=cfg.paths.compile_cache)
            info.dataset = Path(cfg.dataset) if cfg.dataset else dataset_of(run_cfg)
        except Exception as e:
            note = f"{type(e).__name__}: {e}".splitlines()[0]
            print(f"warning: skipping run {info.name}: {note}", file=sys.stderr)
            skipped.append(f"`{info.name}`: {note}")
            continue
        infos.append(info)
    return infos, skipped


def _union(lists) -> list[Path]:
    """The folders of ``lists`` in order, each once (a folder named twice, or by two paths)."""
    folders = {}
    for folder in (p for paths in lists for p in paths):
        folders.setdefault(folder.resolve(), folder)
    return list(folders.values())


def _not_evaluated(run_dir: Path, outputs: Path) -> str:
    """The note of a run left out: its status and, if it failed or stopped, why."""
    status = training_runs.run_status(run_dir)
    error = training_runs.read_run_json(run_dir).get("error") if status != "unreadable" else None
    return f"`{run_name(run_dir, outputs)}`: status {status}" + (f" ({error})" if error else "")


def pick_video_run(runs: list[RunInfo], wanted: str | None) -> RunInfo | None:
    """The run whose OOD rollouts are filmed: ``wanted`` (a name), else the first baseline."""
    learned = [r for r in runs if r.run_dir is not None]
    if wanted:
        match = [r for r in learned if r.name == wanted or str(r.run_dir) == wanted]
        if not match:
            names = ", ".join(r.name for r in learned) or "no learned run"
            raise EvalError(
                f"video_run {wanted} is not among the evaluated runs ({names}): name one of "
                "them, or leave video_run=null to film the first baseline run"
            )
        return match[0]
    order = sorted(
        learned,
        key=lambda r: (
            r.experiment != "baseline",
            config_label(r.overrides) != "default",
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


def constrained_variants(runs: list[RunInfo], iterations: int) -> list[RunInfo]:
    """Each learned run again, followed by ``iterations`` of the constraint stage
    (:mod:`physgnn.models.constrained`), as its own variant: the name and experiment end in
    ``+ constraints`` so that every table shows it beside the pure model. None for 0."""
    if iterations < 1:
        return []
    return [
        dataclasses.replace(
            run,
            name=f"{run.name} + constraints",
            experiment=f"{run.experiment} + constraints",
            simulator=ConstrainedSimulator(run.simulator, iterations),
            extra={**run.extra, "constraints": iterations},
        )
        for run in runs
        if run.run_dir is not None
    ]
