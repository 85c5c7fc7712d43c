"""The one base of every error of the user's making (bad config, missing or corrupt data).

A :class:`PhysgnnError` carries a message of one line that names the problem; every command
(:mod:`physgnn.cli`) prints it as ``error: <message>`` and exits with :attr:`exit_code`.
Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations


class PhysgnnError(Exception):
    """An error of the user's making, told in one line."""

    exit_code = 2


def one_line(err: BaseException) -> str:
    """The message of ``err`` on one line (its non-empty lines joined by ``"; "``)."""
    return "; ".join(line.strip() for line in str(err).splitlines() if line.strip())


class ConfigError(PhysgnnError, ValueError):
    """A config value that cannot be used (missing, of the wrong kind or out of range)."""
