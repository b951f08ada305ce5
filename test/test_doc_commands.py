"""Every command the README and docs/ name exists as named.

A command is a code span or a line of a code block of README.md or of a markdown file under
docs/ (the generated reports included) that starts with ``fence-sorter`` or ``python -m``
(after ``nice``, ``&&`` or environment assignments). ``fence-sorter SUB`` and ``python -m
benchmarks SUB`` must name a subcommand their ``--help`` lists, each ``--option`` of the
command must be one that subcommand's parser accepts, and ``python -m MODULE`` must name a
module of this checkout (a campaign's ``--help`` listing each ``--option`` named). All in this
process: the top-level help is formatted from the same parser the command line builds, and
only the named subcommand's module is imported.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import io
import re
import shlex
from functools import cache
from pathlib import Path

import pytest

from benchmarks import cli as benchmarks_cli
from fence_sorter.cli import main as fence_sorter_cli

REPO = Path(__file__).resolve().parents[1]
DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]

#: the programs whose subcommands are checked: the words that start a command -> the command line
PROGRAMS = {
    ("fence-sorter",): fence_sorter_cli.FENCE_SORTER,
    ("python", "-m", "benchmarks"): benchmarks_cli.BENCHMARKS,
}


def code_texts(markdown: str) -> list[str]:
    """The lines of the fenced code blocks and the code spans outside them."""
    texts: list[str] = []
    for block in re.findall(r"^```[^\n]*\n(.*?)^```", markdown, re.S | re.M):
        texts += block.splitlines()
    prose = re.sub(r"^```[^\n]*\n.*?^```", "", markdown, flags=re.S | re.M)
    texts += re.findall(r"`([^`\n]+)`", prose)
    return texts


def commands_in(text: str) -> list[list[str]]:
    """The commands of one line of code: its parts between ``&&``, ``;`` and ``|``, each from
    ``fence-sorter`` or ``python -m`` on, comments dropped, as words."""
    found = []
    text = text.split(" #", 1)[0].strip().removeprefix("$ ")
    for part in re.split(r"&&|;|\|", text):
        try:
            words = shlex.split(part)
        except ValueError:  # an unbalanced quote: prose in a span, not a command
            continue
        while words and (words[0] in ("nice", "-n") or re.fullmatch(r"\d+|[A-Z_]+=\S*", words[0])):
            words = words[1:]
        if words[:1] == ["fence-sorter"] or words[:2] == ["python", "-m"]:
            found.append(words)
    return found


def documented_commands() -> list[tuple[str, tuple[str, ...]]]:
    """(document, command words) of every command of the documents, each once."""
    seen: dict[tuple[str, ...], str] = {}
    for doc in DOCUMENTS:
        for text in code_texts(doc.read_text(encoding="utf-8")):
            for words in commands_in(text):
                seen.setdefault(tuple(words), str(doc.relative_to(REPO)))
    return [(doc, words) for words, doc in seen.items()]


def listed_subcommands(cli: fence_sorter_cli.CommandLine) -> set[str]:
    """The subcommands the top-level ``--help`` lists."""
    text = fence_sorter_cli.build_parser((), cli).format_help()
    return set(re.findall(r"^ {4}(\S+)", text, re.M))


@cache
def options_of(prog: str, sub: str) -> frozenset[str]:
    """The option strings the subcommand of ``prog`` accepts (its module configures it)."""
    (cli,) = [c for c in PROGRAMS.values() if c.prog == prog]
    parser = fence_sorter_cli.build_parser([sub], cli)
    (action,) = [a for a in parser._actions if a.dest == "command"]
    options = set()

    def collect(p) -> None:
        for a in p._actions:
            options.update(a.option_strings)
            if isinstance(a, argparse._SubParsersAction):  # nested subcommands (bag info)
                for child in a.choices.values():
                    collect(child)

    collect(action.choices[sub])
    return frozenset(options)


@cache
def module_options(module: str) -> frozenset[str]:
    """The options ``python -m MODULE --help`` lists, from its ``main(["--help"])`` run here."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        importlib.import_module(module).main(["--help"])
    return frozenset(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", out.getvalue()))


COMMANDS = documented_commands()


def test_the_documents_name_commands() -> None:
    programs = {words[0] if words[0] != "python" else words[2] for _, words in COMMANDS}
    assert {"fence-sorter", "benchmarks"} <= programs, programs
    assert len(COMMANDS) > 40


@pytest.mark.parametrize(("doc", "words"), COMMANDS, ids=[" ".join(w) for _, w in COMMANDS])
def test_named_command_exists(doc: str, words: tuple[str, ...]) -> None:
    for start, cli in PROGRAMS.items():
        if words[: len(start)] != start:
            continue
        rest = words[len(start) :]
        if not rest or rest[0].startswith(("-", "<", "[", "{", "...")) or rest[0].isupper():
            return  # the program itself or a placeholder for its subcommand
        assert rest[0] in listed_subcommands(cli), (
            f"{doc}: `{' '.join(words)}`: {cli.prog} has no subcommand {rest[0]!r}"
        )
        options = options_of(cli.prog, rest[0])
        unknown = [
            w.split("=", 1)[0]
            for w in rest[1:]
            if w.startswith("--") and w.split("=", 1)[0] not in options
        ]
        assert unknown == [], f"{doc}: `{' '.join(words)}`: {cli.prog} {rest[0]} has no {unknown}"
        return
    module = words[2]
    if module.startswith(("fence_sorter", "benchmarks")):
        assert importlib.util.find_spec(module) is not None, (
            f"{doc}: `{' '.join(words)}`: no module {module}"
        )
    named = [w.split("=", 1)[0] for w in words[3:] if w.startswith("--")]
    if named and module.startswith("benchmarks."):
        unknown = [o for o in named if o not in module_options(module)]
        assert unknown == [], f"{doc}: `{' '.join(words)}`: {module} has no {unknown}"


def test_commands_are_found_in_spans_blocks_and_chains() -> None:
    text = (
        "run `fence-sorter simulate x` or\n"
        "```bash\nnice -n 10 python -m benchmarks bench  # b\n```\n"
    )
    assert [commands_in(t) for t in code_texts(text)] == [
        [["python", "-m", "benchmarks", "bench"]],
        [["fence-sorter", "simulate", "x"]],
    ]
    assert commands_in("source scripts/env.sh && A=1 fence-sorter run --rtf 0") == [
        ["fence-sorter", "run", "--rtf", "0"]
    ]


def test_a_campaigns_options_are_read_from_its_help() -> None:
    assert {"--rounds", "--runs", "--load", "--out"} <= module_options("benchmarks.startup")
    assert {"--dt-max", "--rounds", "--from-json"} <= module_options("benchmarks.dt_max")
    assert "--bogus" not in module_options("benchmarks.dt_max")
