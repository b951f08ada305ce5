"""A command of subcommands (``fence-sorter bag``, ``param``, ``topic``): its parsers, and its
usage on stderr with exit status 2 when it is given no subcommand."""

from __future__ import annotations

import argparse
import sys


def add_subcommands(parser: argparse.ArgumentParser, description: str, dest: str):
    """Describe ``parser`` by ``description`` and return the action its subcommands' parsers
    are added to (their name lands in ``args.<dest>``); given none, it prints its usage."""
    parser.description = description
    parser.set_defaults(func=lambda args: usage(parser))
    return parser.add_subparsers(dest=dest, metavar="COMMAND")


def doc_summary(doc: str) -> str:
    """The first paragraph of a module's docstring as one line of help text (its reST
    ``literals`` in single backquotes)."""
    paragraph = doc.strip().split("\n\n", 1)[0]
    return " ".join(paragraph.split()).replace("``", "`")


def usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help(sys.stderr)
    return 2
