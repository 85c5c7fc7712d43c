"""Keys added with ``+`` on a command line that nothing reads, refused in one line.

Hydra's ``+key=value`` adds a key the config does not have, and Hydra's own hint for a typo
suggests exactly that form: ``+lr=0.01`` or ``+trainer.max_epoch=5`` would then be ignored.
A ``+`` key is taken only where something reads it:

- a config group (``+experiment=ablation_M``);
- an argument of the nearest section above it with a ``_target_`` (``+trainer.limit_val_batches=2``
  is an argument of ``lightning.Trainer``; a target taking ``**kwargs`` takes any);
- a key below a section whose keys are passed on as they are (:data:`OPEN_SECTIONS`);
- Hydra's own settings (``hydra.*``).

Anything else is refused, naming the keys of the config it most resembles.

:func:`check_composes` checks, before Hydra runs, that a command line composes at all: a key
the config lacks (``frame=3``) or an option its group lacks (``scene=x.yaml``) is then one
line too, not Hydra's message of several.
"""

from __future__ import annotations

import difflib
import inspect
import re
from collections.abc import Mapping
from pathlib import Path

from hydra.compose import compose
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import HydraException, MissingConfigException
from hydra.initialize import initialize_config_dir
from hydra.utils import get_object
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from physgnn import CONF_DIR
from physgnn.errors import ConfigError
from physgnn.overrides import key_of, parse_overrides

# Sections whose keys go on to another program as they are (submitit's executor parameters).
OPEN_SECTIONS = ("launcher.slurm",)
HYDRA_KEYS = {"_target_", "_partial_", "_recursive_", "_convert_", "_args_"}


def check_added_keys(cfg: DictConfig, overrides: list[str], command: str) -> None:
    """Refuse the first ``+key=value`` of ``overrides`` that nothing of ``command`` reads."""
    for override in overrides:
        if not override.startswith("+") or override.startswith("++"):
            continue
        problem = _unread(cfg, key_of(override), command)
        if problem:
            raise ConfigError(f"{override}: {problem}")


def check_quoting(argv: list[str]) -> None:
    """An override holding a character Hydra's grammar does not take unquoted (a path with
    ``é``: Hydra says only ``LexerNoViableAltException``) is one line with the quoting fix."""
    parse_overrides([arg for arg in argv if not arg.isascii()])


def compose_config(name: str, overrides: list[str] | None = None) -> DictConfig:
    """``conf/<name>.yaml`` composed with ``overrides``, inside a running Hydra app (its own
    search path) or outside one (a fresh one)."""
    if GlobalHydra.instance().is_initialized():
        return compose(name, overrides=overrides or [])
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(name, overrides=overrides or [])


def check_composes(command: str, argv: list[str], missing: Mapping[str, str] | None = None):
    """``conf/<command>.yaml`` composes with the overrides of ``argv`` (a command line with
    Hydra's own flags, ``--help`` or ``-m``, is left to Hydra), else :class:`ConfigError`, one
    line naming the override: a key the config lacks, with the keys most like it, or an option
    its group lacks, with the group's options and ``missing[group]`` (what to give instead;
    ``{option}`` stands for the option given)."""
    if any(arg.startswith("-") for arg in argv):
        return
    overrides = [arg for arg in argv if not arg.lstrip("+~").startswith("hydra")]
    try:
        compose_config(command, overrides)
    except (HydraException, OmegaConfBaseException) as err:
        raise ConfigError(_not_composed(err, command, overrides, missing or {})) from None


def _not_composed(err: Exception, command: str, overrides: list[str], missing) -> str:
    """The one line of :func:`check_composes`."""
    if isinstance(err, MissingConfigException) and err.missing_cfg_file and err.options:
        group, _, option = err.missing_cfg_file.partition("/")
        given = next(
            (o for o in overrides if o.lstrip("+~").startswith(f"{group}=")), f"{group}={option}"
        )
        extra = f"; {missing[group].format(option=option)}" if group in missing else ""
        return (
            f"{given}: no {option!r} in the config group {group} (options: "
            f"{', '.join(err.options)}){extra}"
        )
    key = re.match(r"Could not override '([^']+)'", str(err))
    if key:
        given = next((o for o in overrides if o.lstrip("+~").startswith(f"{key[1]}=")), key[1])
        config = compose_config(command)
        node = OmegaConf.select(config, key[1])
        added = re.search(r"full_key: (\S+)", str(err.__cause__))  # the key it lacks
        if isinstance(node, DictConfig) and added and added[1].startswith(f"{key[1]}."):
            return (
                f"{given}: {added[1].removeprefix(key[1] + '.')} is not one of the keys of "
                f"{key[1]} ({', '.join(map(str, node)) or 'none'}), and a mapping given on the "
                f"command line is merged into them: to replace the whole mapping, set it to "
                f"null first ({key[1]}=null '{given}')"
            )
        like = _resembling(config, key[1])
        hint = f": did you mean {' or '.join(like)}?" if like else ""
        return f"{given}: {key[1]} is not a key of the {command} config{hint}"
    return str(err).strip().splitlines()[0]


def _unread(cfg: DictConfig, key: str, command: str) -> str | None:
    """Why nothing reads the added ``key``, or None when something does."""
    if key.startswith("hydra") or _is_group(key) or key.startswith(OPEN_SECTIONS):
        return None
    parts = key.split(".")
    for depth in range(len(parts) - 1, 0, -1):
        node = OmegaConf.select(cfg, ".".join(parts[:depth]))
        if isinstance(node, DictConfig) and "_target_" in node:
            return _not_an_argument(node, ".".join(parts[:depth]), parts[depth])
    like = _resembling(cfg, key)
    hint = (
        f"did you mean {' or '.join(like)}? (no '+': it is set like any key)"
        if like
        else "check the key's spelling"
    )
    return (
        f"{key} is not a key of the {command} config and nothing reads it ('+' adds a "
        f"key that is not there): {hint}"
    )


def _is_group(key: str) -> bool:
    """``key`` names a config group (``experiment``, ``scene@ood.x``)."""
    group = key.split("@")[0]
    return (Path(CONF_DIR) / group).is_dir()


def _not_an_argument(node: DictConfig, section: str, name: str) -> str | None:
    """Why ``name`` is not an argument of ``section``'s target (None when it is, or when the
    target cannot be looked up here: the command says so itself)."""
    if name in HYDRA_KEYS:
        return None
    try:
        params = inspect.signature(get_object(node._target_)).parameters
    except (ImportError, ValueError, TypeError, AttributeError):
        return None
    if name in params or any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return None
    known = [k for k in params if k not in ("self", "args", "kwargs")]
    like = [f"{k}.{name}" for k in _nodes_taking(node, name)]  # model.M: model.network.M
    like = like or difflib.get_close_matches(name, known, n=2)
    hint = (
        f"did you mean {' or '.join(f'{section}.{k}' for k in like)}?"
        if like
        else f"known: {', '.join(known)}"
    )
    return f"{section}.{name} is not an argument of {node._target_} ({hint})"


def _nodes_taking(node: DictConfig, name: str) -> list[str]:
    """The keys of ``node``'s ``_target_`` nodes whose target takes the argument ``name``."""
    found = []
    for key in node:
        child = node._get_node(key)
        if isinstance(child, DictConfig) and "_target_" in child:
            try:
                if name in inspect.signature(get_object(child._target_)).parameters:
                    found.append(str(key))
            except (ImportError, ValueError, TypeError, AttributeError):
                continue
    return found


def _resembling(cfg: DictConfig, key: str) -> list[str]:
    """Up to two other keys of ``cfg`` (dotted) whose last part is the most like ``key``'s,
    looked for beside it first, then anywhere."""
    keys = [k for k in _dotted_keys(cfg) if not k.startswith("hydra") and k != key]
    parent, _, name = key.rpartition(".")
    beside = [k for k in keys if k.rpartition(".")[0] == parent]
    for pool in (beside, keys):
        close = difflib.get_close_matches(name, sorted({k.rsplit(".", 1)[-1] for k in pool}), n=1)
        if close:
            return [k for k in pool if k.rsplit(".", 1)[-1] == close[0]][:2]
    return []


def _dotted_keys(node: DictConfig, prefix: str = "") -> list[str]:
    out = []
    for k in node.keys():
        path = f"{prefix}{k}"
        value = node._get_node(k)
        if isinstance(value, DictConfig):
            out += _dotted_keys(value, f"{path}.")
        else:
            out.append(path)
    return out
