"""The values an option takes, declared as data beside it, and the one check of them.

An option group is a frozen dataclass whose numeric fields carry their :class:`Allowed` in the
field's metadata (``rest_speed: float = ranged(number(0, above=True, what="m/s"), default=0.01)``);
a ``bool`` field is true or false without saying so. :func:`check_fields`, called from the
group's ``__post_init__``, checks every field; a value that is not an option of a group (a
command's argument, a constructor's) is checked by :meth:`Allowed.check` alike. Every refusal
is one line in one format, naming the key, the allowed values, the value given and the fix::

    lit.noise.std must be a number >= 0 (normalised units), got -1 (the default: lit.noise.std=0.03)
    frames must be a whole number >= 2 (the first frame is the start), got 1 (e.g. frames=100)

Chosen: **a dataclass field's metadata read by one checker**, neither pydantic nor Hydra's
structured configs. The option groups already are frozen dataclasses built from ``_target_``
(docs/ARCHITECTURE.md, "Configuration of the training recipe"), so a range beside its field
costs no new dependency and no new way to build them; pydantic would add one, and answer with
its own multi-line ``ValidationError``; a structured-config schema would have to be registered
by ``cli`` (the only module that imports Hydra, which must not import the parts whose options
it checks) and OmegaConf would answer with its own message, not this line.
"""

from __future__ import annotations

import difflib
import math
import numbers
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

from physgnn.errors import ConfigError

MAX_SEED = 2**32 - 1
WORDS = {int: "a whole number", float: "a number", bool: "true or false", str: "a string"}


@dataclass(frozen=True)
class Allowed:
    """The values of one option: of ``kind`` (``int``: a whole number, 10.0 too, never 2.5;
    ``float``: a finite number, never NaN; ``bool``; ``str``), between ``least`` and ``most``
    (None: no bound; ``above``/``below``: the bound itself excluded), one of ``choices`` when
    given, or one of ``also`` (``None``: null; ``-1``: no limit). ``what``: its unit or
    meaning; ``example``: a value it takes, for the fix of a refusal; ``exact``: a whole number
    written as one (10, not 10.0), for a value passed on as it is."""

    kind: type = float
    least: float | None = None
    most: float | None = None
    above: bool = False
    below: bool = False
    choices: tuple = ()
    also: tuple = ()
    what: str = ""
    example: Any = None
    exact: bool = False

    def words(self) -> str:
        """``"a whole number >= 1"``, ``"a number in (0, 1]"``, ``"one of a, b"`` ..."""
        if self.choices:
            text = f"one of {', '.join(map(str, self.choices))}"
        else:
            text = WORDS.get(self.kind, self.kind.__name__) + self._bounds()
        extra = ["null" if a is None else str(a) for a in self.also]
        return " or ".join([text, *extra])

    def _bounds(self) -> str:
        low, high = self.least, self.most
        if low is not None and high is not None:
            if self.kind is int and not (self.above or self.below):
                return f" from {low} to {high}"
            return f" in {'(' if self.above else '['}{low:g}, {high:g}{')' if self.below else ']'}"
        if low is not None:
            return f" {'>' if self.above else '>='} {low:g}"
        if high is not None:
            return f" {'<' if self.below else '<='} {high:g}"
        return ""

    def admits(self, value) -> bool:
        """Whether ``value`` is one of the allowed values."""
        if any(value is a or (a is not None and _same(value, a)) for a in self.also):
            return True
        if self.choices:
            return value in self.choices and not isinstance(value, bool)
        if self.kind in (bool, str):
            return isinstance(value, self.kind)
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            return False
        if self.kind is int and (self.exact and not isinstance(value, int)):
            return False
        if not math.isfinite(value) or self.kind is int and not float(value).is_integer():
            return False
        low = self.least is None or (value > self.least if self.above else value >= self.least)
        high = self.most is None or (value < self.most if self.below else value <= self.most)
        return low and high

    def _closest(self, key: str, value) -> str:
        """``did you mean key=<the choice most like value>?``, or ``""`` (no choices, or none
        is close)."""
        like = difflib.get_close_matches(str(value), [str(c) for c in self.choices], n=1)
        return f"did you mean {key}={like[0]}?" if like else ""

    def some_value(self):
        """A value the option takes (:attr:`example`, else one read off the bounds)."""
        if self.example is not None:
            return self.example
        if self.choices:
            return self.choices[0]
        if self.kind is bool:
            return "true"
        low, high = self.least, self.most
        if low is not None and not self.above:
            return low
        if high is not None and not self.below:
            return high
        if low is not None and high is not None:
            return (low + high) / 2
        return 1 if low is None else low + 1

    def check(self, key: str, value, fix: str = "", error: type = ConfigError):
        """``value`` of ``key`` (a whole number as ``int``), else :func:`refuse` naming
        ``key``; ``fix``: the way out (if not given, the choice most like a misspelt value,
        ``did you mean key=<it>?``, else ``e.g. key=<a value it takes>``)."""
        if not self.admits(value):
            fix = fix or self._closest(key, value) or f"e.g. {key}={self.some_value()}"
            raise error(refusal(key, value, self, fix))
        if self.kind is int and value not in self.also and not self.choices:
            return int(value)
        return value


def _same(value, allowed) -> bool:
    """``value`` equals the special value ``allowed`` (``-1``), a flag never."""
    return not isinstance(value, bool) and type(value) in (int, float) and value == allowed


def refusal(key: str, value, allowed: Allowed, fix: str) -> str:
    """The one line of a refused value: key, allowed values (and meaning), value, fix."""
    what = f" ({allowed.what})" if allowed.what else ""
    return f"{key} must be {allowed.words()}{what}, got {value!r} ({fix})"


def whole(least: int | None = 0, most: int | None = None, **kw) -> Allowed:
    """Whole numbers from ``least`` (to ``most``)."""
    return Allowed(int, least, most, **kw)


def number(least: float | None = None, most: float | None = None, **kw) -> Allowed:
    """Finite numbers from ``least`` (to ``most``; ``above=True``: ``least`` excluded)."""
    return Allowed(float, least, most, **kw)


def one_of(*choices, **kw) -> Allowed:
    return Allowed(str, choices=choices, **kw)


FLAG = Allowed(bool)
SEED = whole(0, MAX_SEED, example=0)  # what numpy, torch and Python all take


def check_seed(seed, key: str = "seed", where: str = "conf/train.yaml: seed") -> int:
    """``seed`` (the config's ``key``, set in ``where``) is a whole number that numpy, torch
    and Python all take: 0 to 2³² − 1."""
    return SEED.check(key, seed, f"{where}; e.g. {key}=0")


def ranged(allowed: Allowed, default=MISSING):
    """A dataclass field whose values are ``allowed`` (read by :func:`check_fields`), of
    ``default`` if given."""
    return field(default=default, metadata={"allowed": allowed})


def allowed_of(group, name: str) -> Allowed:
    """The :class:`Allowed` of the field ``name`` of the dataclass ``group`` (a ``bool`` field:
    :data:`FLAG`)."""
    found = next(f for f in fields(group) if f.name == name)
    return found.metadata.get("allowed") or (FLAG if found.type in ("bool", bool) else Allowed())


def check_fields(group, error: type = ConfigError) -> None:
    """Every field of the option group ``group`` (a dataclass with a ``NODE``, its key in the
    config, ``""`` for top-level keys) that declares its allowed values, and every ``bool``
    field, holds one of them (a whole number kept as ``int``: 2.0 is 2); the fix of a refusal
    is the field's default when it has one."""
    for f in fields(group):
        if "allowed" not in f.metadata and f.type not in ("bool", bool):
            continue
        key = f"{group.NODE}.{f.name}" if group.NODE else f.name
        default = None if f.default is MISSING else f.default
        fix = f"the default: {key}={_yaml(default)}" if default is not None else ""
        value = allowed_of(group, f.name).check(key, getattr(group, f.name), fix, error)
        object.__setattr__(group, f.name, value)  # a frozen group: its own __post_init__


def _yaml(value) -> str:
    """``value`` as a command line writes it (``true``, not ``True``)."""
    return str(value).lower() if isinstance(value, bool) else str(value)
