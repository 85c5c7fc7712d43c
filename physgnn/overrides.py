"""The one reading of a ``key=value`` override of a command line: Hydra's own grammar
(``OverridesParser``), so that every part reads ``+key=v``, ``~key``, ``key@pkg=v``,
``key="a b"`` and the sweeps ``key=1,2`` or ``range(0,3)`` as Hydra will. In base because the
parts below ``cli`` read overrides too (a run's record, a sweep's, a resume's); an override
Hydra cannot read is one line with the fix (:class:`~physgnn.errors.ConfigError`)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException

from physgnn.errors import ConfigError, one_line


@dataclass(frozen=True)
class Override:
    """``key`` without its prefix (``lit.noise.std``, ``scene@ood.x``), ``prefix`` (``+``,
    ``++``, ``~`` or ``""``), the value ``written`` as given (quotes kept; ``""`` for a
    deletion without one), its Python ``value`` (``3``, ``None``; a sweep's text), whether it
    is a ``sweep`` and the ``values`` it takes (``range(0,3)``: 0, 1, 2; else ``value``)."""

    key: str
    prefix: str
    written: str
    value: Any
    sweep: bool
    values: tuple

    @property
    def written_key(self) -> str:
        """The key as written, its prefix kept (``+variant``)."""
        return self.prefix + self.key


@functools.cache
def _parser() -> OverridesParser:
    return OverridesParser.create()


def parse_override(text: str) -> Override:
    """``text`` read as Hydra reads an override; else one line naming it and the fix."""
    try:
        parsed = _parser().parse_override(text)
    except HydraException as err:
        raise ConfigError(_unreadable(text, err)) from None
    element = parsed.get_key_element()
    key = element.lstrip("+~")
    written = parsed.get_value_string() if parsed.value_type is not None else ""
    sweep = parsed.is_sweep_override()
    value = written if sweep or parsed.value_type is None else parsed.value()
    values = tuple(parsed.sweep_iterator()) if sweep else (value,)
    return Override(key, element[: len(element) - len(key)], written, value, sweep, values)


def parse_overrides(argv: list[str]) -> list[Override]:
    """The overrides of a command line ``argv``: Hydra's flags and their values (``-m``,
    ``--cfg job``) left out, as is an argument that neither sets nor deletes a key (Hydra
    names it)."""
    args = [str(arg) for arg in argv]
    return [parse_override(a) for a in args if not a.startswith("-") and ("=" in a or a[:1] == "~")]


def given(argv: list[str]) -> dict[str, Override]:
    """The overrides of ``argv`` that set a value, by key (``run_dir=x``: ``"run_dir"``)."""
    return {o.key: o for o in parse_overrides(argv) if o.prefix != "~"}


def key_of(text: str) -> str:
    """The key of the override ``text`` (``+lit.compile.enabled=true``:
    ``lit.compile.enabled``)."""
    return parse_override(text).key


def _unreadable(text: str, err: Exception) -> str:
    """Why Hydra cannot read ``text``, and the fix: a character its grammar takes only in
    quotes (``é``: Hydra says only ``LexerNoViableAltException``), or its own first line."""
    key, sep, value = text.partition("=")  # the fix quotes what the user wrote after '='
    odd = next((c for c in text if not c.isascii()), None)
    if odd is not None and sep:
        quoted = f"'{key}=\"{value}\"'"
        return (
            f"{key}: Hydra reads a value with {odd!r} only in quotes: write {quoted} (the shell's "
            "quotes around Hydra's)"
        )
    return f"{text}: not an override Hydra reads ({one_line(err)[:200]}): write key=value"
