"""Markdown from the verification commands' JSON: the table functions every renderer shares.

Each command (``fence-sorter accuracy``, ``stability``, ``bench``) writes its figures as JSON
and renders its markdown from that JSON alone, so the committed markdown can be rebuilt from
the committed data (and a test checks that its tables are). Interpretation of the figures is
written for readers in docs/design/verification.md, not generated.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence


def fmt(value, spec: str = ".2e", missing: str = "n/a") -> str:
    """``value`` formatted with ``spec``; ``missing`` for None, NaN and infinities."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return missing
    return f"{value:{spec}}"


def table(header: Sequence[str], rows: Iterable[Sequence[object]]) -> list[str]:
    """A markdown table: a header row, the separator, one line per row (cells as str)."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return out


def tables(markdown: str) -> list[list[str]]:
    """The tables of a markdown text: each a list of its lines, in order."""
    found: list[list[str]] = []
    current: list[str] = []
    for line in markdown.splitlines():
        if line.startswith("|"):
            current.append(line.rstrip())
        elif current:
            found.append(current)
            current = []
    if current:
        found.append(current)
    return found


__all__ = ["fmt", "table", "tables"]
