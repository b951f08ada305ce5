"""The marked sections of a document that a campaign rewrites, the rest kept as it is.

A campaign whose figures stand in a longer document (docs/design/numerics.md's convergence,
the node-suite part of docs/reports/benchmarks.md, ...) renders them between two marker
comments of its own; these functions are the one place that finds and replaces them.
"""

from __future__ import annotations

from pathlib import Path


def _span(text: str, begin: str, end: str) -> tuple[int, int] | None:
    """Where the first ``begin`` and the first ``end`` after it stand (None: no section)."""
    a = text.find(begin)
    b = text.find(end, a + len(begin)) if a >= 0 else -1
    return (a, b + len(end)) if b >= 0 else None


def has_section(text: str, begin: str, end: str) -> bool:
    """Whether ``text`` holds ``begin`` followed by ``end``."""
    return _span(text, begin, end) is not None


def section_of(text: str, begin: str, end: str) -> str:
    """The marked section of ``text``, markers included ("" when it has none)."""
    span = _span(text, begin, end)
    return text[span[0] : span[1]] if span else ""


def replace_section(path: Path, section: str, begin: str, end: str, append: bool = False) -> None:
    """Replace the marked section of ``path`` by ``section`` (which carries the markers); a
    document without one gets it appended when ``append``, else ValueError."""
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    span = _span(text, begin, end)
    if span:
        text = text[: span[0]] + section + text[span[1] :]
    elif append:
        text = text.rstrip("\n") + ("\n\n" if text else "") + section + "\n"
    else:
        raise ValueError(f"{path} has no section between {begin} and {end}")
    path.write_text(text, encoding="utf-8")
