"""Checks of the run folder a training writes into and of the checkpoint it starts from, each
failing in one line that names the folder or the file: a folder in use by a live training, or
holding what physgnn did not write or another run's checkpoints, is never trained over; an
interrupted run there resumes only with the overrides and the dataset it started with; a
checkpoint must read whole and fit the model."""

from __future__ import annotations

import socket
from pathlib import Path

import torch
from lightning.pytorch.utilities.rank_zero import rank_zero_only
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import ConfigError
from physgnn.locks import process_alive
from physgnn.overrides import given, key_of
from physgnn.training.datamodule import dataset_identity
from physgnn.training.layout import check_renamed, dotted_model, key_of_today, model_of_today
from physgnn.training.runlog import LOG_NAME
from physgnn.training.runs import RUN_JSON, load_checkpoint, read_run_json, run_status

# A run folder in one of these states is resumed from its last.ckpt when trained again (a
# requeued cluster job; a run killed outright; a run whose restart had a config mistake); any
# other run with checkpoints (finished, truncated, diverged, debug) is never trained over.
RESUMABLE = ("interrupted", "running", "failed")
# What a training's folder holds before its run.json is written: Hydra's config files and log.
BEFORE_RUN_JSON = (".hydra", LOG_NAME)
# Every status physgnn writes into a run.json (physgnn/training/train.py, export.py).
STATUSES = ("running", "finished", "truncated", "interrupted", "diverged", "failed", "debug")


def check_not_running(run_dir: Path) -> None:
    """A ``run_dir`` whose run.json says ``running`` for a process alive on this host is in
    use: refused in one line naming it. A ``running`` record of a dead process (a run killed
    outright), or of another host (a requeued cluster job), is taken over."""
    if rank_zero_only.rank != 0:  # DDP's other processes: rank 0 holds the folder for them
        return
    info = read_run_json(run_dir) if run_status(run_dir) == "running" else {}
    if info.get("host") == socket.gethostname() and process_alive(info.get("pid")):
        raise ConfigError(
            f"run_dir {run_dir} is in use: a training started {info.get('started')} runs there "
            f"(pid {info['pid']} on {info['host']}): wait for it to end, stop it (kill "
            f"{info['pid']}: it saves last.ckpt, then train again there to resume), or choose "
            "another run_dir"
        )


def check_run_dir(cfg: DictConfig, run_dir: Path, overrides: list[str] | None = None) -> None:
    """A ``run_dir`` in use by a live training is refused (:func:`check_not_running`), and so
    is one holding a run.json physgnn did not write, or other files and no run.json
    (:func:`check_not_users`); one holding another run's checkpoints is never trained over:
    only an interrupted run there is resumed, from its own ``last.ckpt``, with the overrides
    it was started with (``overrides``: this session's, when known)."""
    check_not_running(run_dir)
    check_own_run_json(run_dir)
    if overrides is not None:
        check_resume_overrides(run_dir, overrides)
    check_resume_data(cfg, run_dir)
    status = run_status(run_dir) if (run_dir / RUN_JSON).exists() else None
    last = run_dir / "checkpoints" / "last.ckpt"
    if not any((run_dir / "checkpoints").glob("*.ckpt")):
        check_not_users(run_dir)
        return
    explicit = cfg.get("ckpt_path")
    if status not in RESUMABLE or explicit and Path(explicit).resolve() != last.resolve():
        raise ConfigError(
            f"run_dir {run_dir} already holds a {status or 'training'} run with checkpoints "
            f"and is never trained over: choose another run_dir (to train that run further, "
            f"ckpt_path={last} in a new run_dir)"
        )


def check_own_run_json(run_dir: Path) -> None:
    """A ``run.json`` in ``run_dir`` that physgnn did not write (no training status) is the
    user's: refused, never replaced."""
    if (run_dir / RUN_JSON).exists() and run_status(run_dir) not in STATUSES:
        raise ConfigError(
            f"run_dir {run_dir} holds a {RUN_JSON} that physgnn did not write (no training "
            "status in it): choose another run_dir (physgnn never replaces it)"
        )


def check_not_users(run_dir: Path) -> None:
    """A ``run_dir`` without run.json that holds more than what Hydra writes there before it
    (:data:`BEFORE_RUN_JSON`) is the user's: refused, nothing in it replaced or appended to.
    An absent or empty folder is trained in."""
    if (run_dir / RUN_JSON).exists() or not run_dir.is_dir():
        return
    others = sorted(p.name for p in run_dir.iterdir() if p.name not in BEFORE_RUN_JSON)
    if others:
        more = f" and {len(others) - 1} more" if len(others) > 1 else ""
        raise ConfigError(
            f"run_dir {run_dir} is a folder with files that physgnn did not write ({others[0]}"
            f"{more}; no {RUN_JSON}): choose another run_dir (a new or empty folder)"
        )


def resumed_here(run_dir: Path) -> bool:
    """Whether training in ``run_dir`` resumes the interrupted run there."""
    last = run_dir / "checkpoints" / "last.ckpt"
    return (run_dir / RUN_JSON).exists() and run_status(run_dir) in RESUMABLE and last.is_file()


def _changeable(override: str) -> bool:
    """Whether ``override`` must be the same on a resume: all but the folder named, the run's
    name in the loggers (a study's job started before it had one) and Hydra's own settings."""
    key = key_of(override)
    return key not in ("run_dir", "ckpt_path", "run_name") and not key.startswith("hydra")


def check_resume_overrides(run_dir: Path, overrides: list[str]) -> None:
    """A resume of the run in ``run_dir`` with other ``overrides`` than it started with is
    refused (the run would mix two configs and its record lose the first)."""
    if not resumed_here(run_dir):
        return
    then = {key_of_today(o) for o in read_run_json(run_dir).get("overrides") or []}
    then = {o for o in then if _changeable(o)}  # a run of an earlier layout: today's spelling
    now = {o for o in overrides if _changeable(o)}
    if then != now:
        gone, new = sorted(then - now), sorted(now - then)
        raise ConfigError(
            f"run_dir {run_dir} resumes a run started with other overrides (missing: "
            f"{' '.join(gone) or 'none'}; new: {' '.join(new) or 'none'}): resume with "
            f"exactly {' '.join(sorted(then)) or 'no overrides'} and run_dir={run_dir}, or "
            "train further in a new run_dir with ckpt_path=<its last.ckpt>"
        )


def check_resume_data(cfg: DictConfig, run_dir: Path) -> None:
    """A resume of the run in ``run_dir`` on another dataset than it was trained on (the
    ``sha256`` of run.json's ``dataset`` against today's, :func:`dataset_identity`: another
    seed or preset at the same path, or another ``PHYSGNN_OUTPUTS``) is refused in one line."""
    if not resumed_here(run_dir) or cfg.get("ckpt_path"):
        return
    then = read_run_json(run_dir).get("dataset") or {}
    try:
        data_dir = OmegaConf.select(cfg, "datamodule.data_dir", throw_on_missing=False)
    except Exception:  # an interpolation that only resolves inside Hydra: train() checks again
        return
    now = dataset_identity(str(data_dir), "") if data_dir else {}
    if then.get("sha256") and now.get("sha256") and then["sha256"] != now["sha256"]:
        last = run_dir / "checkpoints" / "last.ckpt"
        raise ConfigError(
            f"run_dir {run_dir} resumes a run trained on another dataset: {then.get('dir')} "
            f"(sha256 {then['sha256'][:12]}) then, {data_dir} (sha256 {now['sha256'][:12]}) now:"
            " resume with the dataset it was trained on (data=, data.dir=, PHYSGNN_OUTPUTS as "
            f"then), or train on from its weights in a new run_dir (ckpt_path={last} "
            "run_dir=<a new folder>)"
        )


def check_resume_argv(argv: list[str]) -> None:
    """A flat recipe key of an earlier physgnn refused naming today's
    (:func:`~physgnn.training.layout.check_renamed`), then :func:`check_resume_overrides` on a
    command line, before Hydra rewrites the run's ``.hydra`` folder: ``run_dir=X`` naming an
    interrupted run."""
    check_renamed(argv)
    run_dir = given(argv).get("run_dir")
    if run_dir is not None and run_dir.value:
        check_resume_overrides(Path(str(run_dir.value)), [a for a in argv if "=" in a])


def resume_from(cfg: DictConfig, run_dir: Path) -> str | None:
    """The checkpoint this run starts from: ``ckpt_path`` (checked), else the ``last.ckpt``
    of an interrupted run in ``run_dir`` itself (:func:`check_run_dir`), else None."""
    explicit = cfg.get("ckpt_path")
    if explicit:
        if not Path(explicit).is_file():
            raise ConfigError(
                f"ckpt_path={explicit}: no such file (a run keeps its checkpoints in "
                "<run_dir>/checkpoints/, last.ckpt the latest)"
            )
        return str(explicit)
    status = run_status(run_dir) if (run_dir / RUN_JSON).exists() else None
    last = run_dir / "checkpoints" / "last.ckpt"
    return str(last) if status in RESUMABLE and last.is_file() else None


def check_checkpoint(path: str | None, lit: torch.nn.Module, model_cfg=None) -> int:
    """The global step of the checkpoint at ``path`` (0 without one), after checking that
    it reads whole (else one line naming it and the run's best checkpoint that does) and that
    its weights fit ``lit`` (same names and shapes), naming the keys of ``model_cfg`` that
    differ from its run's config."""
    if path is None:
        return 0
    way_out = "train on from {other} in a new run_dir (ckpt_path={other} run_dir=<a new folder>)"
    ckpt = load_checkpoint(Path(path), way_out, weights_only=True, mmap=True)
    if not isinstance(ckpt, dict) or "state_dict" not in ckpt:
        raise ConfigError(f"ckpt_path={path} is not a training checkpoint (no state_dict)")
    state = ckpt["state_dict"]
    model = lit.state_dict()
    wrong = sorted(set(model) ^ set(state))
    wrong += [k for k in model if k in state and model[k].shape != state[k].shape]
    if wrong:
        raise ConfigError(
            f"ckpt_path={path} does not fit this model ({_model_difference(path, model_cfg)}"
            f"{len(wrong)} weights differ, e.g. {wrong[0]}): resume with the model settings "
            "it was trained with"
        )
    return int(ckpt.get("global_step", 0))


def _model_difference(path: str, model_cfg) -> str:
    """``"model.network.M is 1 there, 2 here; "``: the model keys in which the config of the
    checkpoint's run (``<run>/.hydra/config.yaml``, in today's layout) and ``model_cfg``
    differ."""
    saved = Path(path).parent.parent / ".hydra" / "config.yaml"
    if model_cfg is None or not saved.is_file():
        return ""
    try:
        then = dotted_model(model_of_today(OmegaConf.load(saved).model))
    except Exception:  # an unreadable or foreign config: no detail to give
        return ""
    now = dotted_model(model_cfg)
    keys = sorted(set(then) | set(now))
    return "".join(
        f"model.{k} is {then.get(k)!r} there, {now.get(k)!r} here; "
        for k in keys
        if then.get(k) != now.get(k)
    )
