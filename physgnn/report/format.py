"""Numbers and tables in markdown, the same way in every report (report.md, bench.md)."""

from __future__ import annotations

import math


def fmt(x: float | None) -> str:
    if x is None or not math.isfinite(x):
        return "–"
    if x == 0:
        return "0"
    if 1e-2 <= abs(x) < 1e4:
        return f"{x:.3g}"
    return f"{x:.2e}"


def fmt_as(x: float | None, spec: str = ".1f") -> str:
    """``x`` in the format ``spec``; "–" for None (not measured)."""
    return "–" if x is None else f"{x:{spec}}"


def fmt_stat(s: tuple[float, float, int] | None) -> str:
    return "–" if s is None else f"{fmt(s[0])} ± {fmt(s[1])}"


def md_table(header: list[str], body: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return "\n".join(lines)
