"""The marked sections of a document that a campaign rewrites, the rest kept as it is.

A campaign whose figures stand in a longer document (docs/design/numerics.md's convergence,
the node-suite part of docs/reports/benchmarks.md, ...) renders them between two marker
comments of its own; these functions are the one place that finds and replaces them.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
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


def framed(begin: str, end: str, source: str, command: str, body: list[str]) -> str:
    """A rendered section: the marks around ``body``, with the command and the JSON (``source``)
    it is written from, so a reader knows not to edit it by hand."""
    note = f"<!-- written by `{command}` from {source}; do not edit by hand -->"
    return "\n".join([begin, note, "", *body, "", end])


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


@dataclass(frozen=True)
class SectionReport:
    """A campaign whose figures go to a JSON and are rendered into a marked section of a
    document: its ``--json``, ``--doc`` and ``--from-json`` options, their checks and writing."""

    name: str  # the campaign, as its error lines name it
    json_path: Path
    doc_path: Path
    begin: str
    end: str
    render: Callable[[dict], str]

    def add_arguments(self, ap: argparse.ArgumentParser) -> None:
        ap.add_argument("--json", default=str(self.json_path), help="the figures' file ('': none)")
        ap.add_argument(
            "--doc", default=str(self.doc_path), help="the document whose section is rewritten"
        )
        ap.add_argument(
            "--from-json", metavar="PATH", help="render this JSON into --doc, measuring nothing"
        )

    def rendered_again(self, ap: argparse.ArgumentParser, args: argparse.Namespace) -> str | None:
        """Check ``--doc`` (exit 2 when it has no section); the section ``--from-json`` renders,
        None when the campaign is to measure."""
        if args.doc:
            try:
                text = Path(args.doc).read_text(encoding="utf-8")
            except OSError as exc:
                ap.error(f"--doc: {exc}")
            if not has_section(text, self.begin, self.end):
                ap.error(f"--doc: {args.doc} has no section between {self.begin} and {self.end}")
        if not args.from_json:
            return None
        try:
            return self.render(json.loads(Path(args.from_json).read_text(encoding="utf-8")))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            ap.error(f"--from-json: {args.from_json}: not a {self.name} report ({exc})")

    def write(self, section: str, data: dict | None, args: argparse.Namespace) -> int:
        """Print the section; write the JSON (when measured) and the document where asked."""
        print(section)
        if data is not None and args.json:
            Path(args.json).write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
            print(f"written: {args.json}", file=sys.stderr)
        if args.doc:
            replace_section(Path(args.doc), section, self.begin, self.end)
            print(f"written: {args.doc}", file=sys.stderr)
        return 0
