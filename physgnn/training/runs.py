"""A training run on disk: ``<run_dir>/run.json``, ``.hydra/config.yaml`` and
``checkpoints/{best-*,last}.ckpt``; :func:`load_run` rebuilds its trained simulator.

No Lightning here: evaluation loads runs without importing the trainer.
"""

from __future__ import annotations

import copy
import difflib
import json
import socket
import zipfile
from pathlib import Path

import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import PhysgnnError, one_line
from physgnn.files import write_json
from physgnn.locks import process_alive
from physgnn.models.learned import LearnedSimulator
from physgnn.training.layout import lit_of_today, model_of_today

RUN_JSON = "run.json"
# The trained simulator shipped with physgnn, a run folder of weights only
# (physgnn/training/export.py); ``run=pretrained`` names it wherever a run folder is taken.
PRETRAINED = "pretrained"
PRETRAINED_DIR = Path(__file__).resolve().parents[1] / "pretrained"
# The layout of an exported run's weights; a run of another layout is refused in one line.
WEIGHTS_FORMAT = 1
GIVE_A_RUN = f"give a run folder (outputs/runs/<experiment>/<time>) or {PRETRAINED}"


class RunError(PhysgnnError, ValueError):
    """A run folder's weights cannot be loaded by this physgnn (one-line message)."""


class RunMissing(RunError, FileNotFoundError):
    """A run folder, or the files a run needs, not there (one-line message)."""


def resolve_run(run: str | Path) -> Path:
    """The run folder ``run`` names: the shipped weights for ``pretrained`` (a one-line error
    where this checkout has none, or for a misspelt ``pretrained`` that is no folder), else the
    path."""
    if str(run) != PRETRAINED:
        if not Path(run).exists() and difflib.get_close_matches(str(run), [PRETRAINED]):
            raise RunMissing(
                f"run folder {run} does not exist: did you mean {PRETRAINED}? Else " + GIVE_A_RUN
            )
        return Path(run)
    if not (PRETRAINED_DIR / RUN_JSON).is_file():
        raise RunError(
            "run=pretrained: this checkout ships no trained weights yet (physgnn/pretrained is "
            "empty); train a model (make train) and pass run=<its run folder>"
        )
    return PRETRAINED_DIR


def write_run_json(run_dir: str | Path, info: dict) -> Path:
    """``run.json`` of a run (status, experiment, overrides, seed, figures), atomically."""
    return write_json(Path(run_dir) / RUN_JSON, info)


def read_run_json(run_dir: str | Path) -> dict:
    """``run.json`` of a run; ``{}`` when there is none."""
    path = Path(run_dir) / RUN_JSON
    return json.loads(path.read_text()) if path.exists() else {}


def run_status(run_dir: Path) -> str:
    """``status`` of a run's run.json (``"unreadable"`` when it cannot be read)."""
    try:
        return str(json.loads((Path(run_dir) / RUN_JSON).read_text()).get("status"))
    except (OSError, ValueError):
        return "unreadable"


def training_now(run_dir: Path) -> dict:
    """run.json of a run whose training is alive on this host now (status ``running``, its
    process alive), else ``{}``: its checkpoints are mid-run."""
    info = read_run_json(run_dir) if run_status(run_dir) == "running" else {}
    alive = info.get("host") == socket.gethostname() and process_alive(info.get("pid"))
    return info if alive else {}


def check_not_training(run_dir: Path, what: str, error: type = None) -> None:
    """A run still training is refused in one line (``what``: what waits for it to end;
    ``error``: the class raised, :class:`RunError` by default)."""
    info = training_now(run_dir)
    if info:
        raise (error or RunError)(
            f"run {run_dir} is still training (pid {info.get('pid')} on {info.get('host')}, "
            f"started {info.get('started')}): its checkpoints are mid-run; {what} when it has "
            "finished"
        )


# What a run's status must be for its weights to be used (eval evaluates it, ship ships it):
# finished, or truncated (its step budget cut short by the time guard).
DONE = ("finished", "truncated")


def check_done(run_dir: Path, what: str, error: type = None) -> None:
    """A run that is not :data:`DONE` (still training, interrupted, failed, diverged, debug, no
    run.json) is refused in one line (``what``: what waits for it; ``error``: the class raised,
    :class:`RunError` by default)."""
    check_not_training(run_dir, what, error)
    status = run_status(run_dir)
    if status not in DONE:
        resume = " (train again there to resume it)" if status in ("interrupted", "running") else ""
        raise (error or RunError)(
            f"run {run_dir} has not finished (run.json status is '{status}'): {what} when it "
            f"has finished{resume}"
        )


def checkpoint_of(run_dir: Path) -> Path:
    """The best checkpoint of a run, else its last one. Several ``best-*`` files (a run
    resumed after its folder moved: Lightning then forgets the best score so far and keeps
    the earlier file) are told apart by the score each was saved with (the latest on a tie
    or where none is found)."""
    best = sorted((run_dir / "checkpoints").glob("best-*.ckpt"))
    last = run_dir / "checkpoints" / "last.ckpt"
    if len(best) > 1:
        return min(enumerate(best), key=lambda item: (_own_score(item[1]), -item[0]))[1]
    if best:
        return best[-1]
    if last.exists():
        return last
    raise RunMissing(f"no checkpoint in {run_dir / 'checkpoints'} (did the run finish an epoch?)")


def _own_score(path: Path) -> float:
    """The monitored score a checkpoint was saved with, lower is better (ModelCheckpoint's
    ``current_score``; negated for ``mode='max'``); +inf where it holds none."""
    try:
        callbacks = torch.load(path, map_location="cpu", weights_only=False).get("callbacks", {})
    except (OSError, RuntimeError, AttributeError):
        return float("inf")
    for key, state in callbacks.items():
        score = state.get("current_score") if isinstance(state, dict) else None
        if str(key).startswith("ModelCheckpoint") and score is not None:
            return -float(score) if "'mode': 'max'" in str(key) else float(score)
    return float("inf")


def load_run(run_dir: str | Path) -> tuple[LearnedSimulator, DictConfig, dict]:
    """``(simulator, cfg, info)`` of a finished run (or ``pretrained``): the simulator from
    ``.hydra/config.yaml`` (its model and recipe in today's layout:
    :mod:`physgnn.training.layout`) and the best (else last) checkpoint, in eval mode on the
    CPU; ``info`` is run.json (plus ``checkpoint``, the file loaded). Weights
    of another format or that do not fit the model this physgnn builds from the config are
    refused in one line."""
    run_dir = resolve_run(run_dir)
    config = run_dir / ".hydra" / "config.yaml"
    if not config.exists():
        what = "is not a training run (no .hydra/config.yaml)" if run_dir.is_dir() else ""
        raise RunMissing(f"run folder {run_dir} {what or 'does not exist'}: {GIVE_A_RUN}")
    check_not_training(run_dir, "load it")
    info = read_run_json(run_dir)
    _check_format(run_dir, info.get("weights_format", WEIGHTS_FORMAT))
    cfg = read_run_config(config)
    cfg.run_dir = str(run_dir)
    cfg.model = model_of_today(cfg.model)  # a run of an earlier physgnn: its own model
    if "lit" in cfg:
        cfg.lit = lit_of_today(cfg.lit)  # ... and its own recipe, in today's groups
    path = checkpoint_of(run_dir)
    way_out = f"move {path.name} away to load {{other}} instead, or train the run again"
    state = load_checkpoint(path, way_out)["state_dict"]
    state = {
        k.removeprefix("simulator."): v for k, v in state.items() if k.startswith("simulator.")
    }
    simulator = instantiate(cfg.model, stats=LearnedSimulator.stats_from_state_dict(state))
    try:
        simulator.load_state_dict(state)
    except RuntimeError:
        raise RunError(
            f"{path} does not fit the model {config} describes ({weights_difference(state, cfg)})"
            ": the weights and the config are of different runs; put the run's own "
            ".hydra/config.yaml back, or use the weights of this config"
        ) from None
    simulator.eval()
    info["checkpoint"] = str(path)
    return simulator, cfg, info


def read_run_config(path: Path) -> DictConfig:
    """A run's ``.hydra/config.yaml``; one that is not a readable config is one line naming
    it."""
    try:
        cfg = OmegaConf.load(path)
    except Exception as err:  # YAML syntax, an unreadable file, ...
        raise RunError(
            f"{path} is not a readable config ({one_line(err)[:200]}): restore it (a copy of the "
            "run's, or the train command with the overrides run.json lists writes it), or train "
            "the run again"
        ) from None
    if not isinstance(cfg, DictConfig) or not isinstance(cfg.get("model"), DictConfig):
        raise RunError(
            f"{path} is not a training run's config (no model section): restore the run's own "
            ".hydra/config.yaml, or train the run again"
        )
    return cfg


def load_checkpoint(path: Path, way_out: str, **kwargs) -> dict:
    """``torch.load`` of the checkpoint ``path`` on the CPU (``kwargs``: its options); one
    that is truncated or corrupt is one line naming it and ``way_out``, in which ``{other}``
    stands for the checkpoints beside it that read whole (the best first)."""
    path = Path(path)
    try:
        return torch.load(path, map_location="cpu", **kwargs)
    except (FileNotFoundError, PermissionError):
        raise
    except Exception as err:  # a zip cut short, not a zip, a pickle torch refuses
        reason = (str(err).splitlines() or [type(err).__name__])[0][:120]
        others = whole_checkpoints(path.parent, but=path)
        fix = (
            way_out.format(other=others[0])
            if others
            else (f"no other checkpoint in {path.parent} reads whole: train the run again")
        )
        raise RunError(f"{path} is truncated or corrupt ({reason}): {fix}") from None


def whole_checkpoints(folder: Path, but: Path | None = None) -> list[Path]:
    """The checkpoints of ``folder`` (but ``but``) whose zip reads whole, the best first."""
    found = sorted(Path(folder).glob("best-*.ckpt"), reverse=True) + [folder / "last.ckpt"]
    whole = []
    for path in found:
        if path.is_file() and path != but:
            try:
                with zipfile.ZipFile(path) as z:
                    if z.testzip() is None:
                        whole.append(path)
            except (OSError, zipfile.BadZipFile):
                continue
    return whole


# The model keys that set the shapes of the weights, tried one at a time by
# :func:`weights_difference` (each with the values listed, besides the one the config has).
SHAPE_KEYS = {
    "network.M": range(1, 17),
    "network.hidden": (),
    "H": range(0, 9),
    "network.num_materials": range(0, 9),
    "network.material_dim": range(0, 33),
    "inputs.boundary_features": (False, True),
    "inputs.contact_features": (False, True),
    "inputs.material_features": (False, True),
    "inputs.relative_pairs": (False, True),
    "inputs.mass_ratio": (False, True),
    "contacts.rest_decision": (False, True),
    "network.use_surfaces": (False, True),
}


def weights_difference(state: dict, cfg: DictConfig) -> str:
    """``"model.network.M is 1 in the weights, 2 in the config"``: the one model key (of
    :data:`SHAPE_KEYS`) whose other value builds a model the weights ``state`` fit; else the
    first weight that differs."""
    shapes = {k: tuple(v.shape) for k, v in state.items()}
    stats = LearnedSimulator.stats_from_state_dict(state)
    encoder = shapes.get("network.node_encoder.lin1.weight")
    for key, values in SHAPE_KEYS.items():
        now = OmegaConf.select(cfg.model, key, default=None)
        tried = [encoder[0]] if key == "network.hidden" and encoder else list(values)
        for value in tried:
            if value == now or now is None:
                continue
            other = copy.deepcopy(cfg.model)
            OmegaConf.update(other, key, value)
            try:
                model = instantiate(other, stats=stats)
            except Exception:  # a value this model cannot take
                continue
            if {k: tuple(v.shape) for k, v in model.state_dict().items()} == shapes:
                return f"model.{key} is {value!r} in the weights, {now!r} in the config"
    model = instantiate(cfg.model, stats=stats).state_dict()
    for key in sorted(set(model) | set(shapes)):
        there, here = shapes.get(key), tuple(model[key].shape) if key in model else None
        if there != here:
            return f"{key}: {there or 'absent'} in the weights, {here or 'absent'} in the model"
    return "the weights differ"


def _check_format(run_dir: Path, found) -> None:
    if found != WEIGHTS_FORMAT:
        raise RunError(
            f"{run_dir} holds weights of format {found}; this physgnn reads format "
            f"{WEIGHTS_FORMAT}: export the run again with this version (make ship RUN=...)"
        )
