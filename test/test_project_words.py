"""Documents, code and tests describe the project as it is, not how it was made.

Every text file under docs/, fence_sorter/ and test/ and the README is searched for the words
of a lab notebook (numbered work periods, people named by initials or role, scratch scripts in
/tmp; the patterns are in FORBIDDEN). History lives in git. Technical uses of the same words
(process groups, pytest's scopes, functions) are named in LEGITIMATE and removed from a line
before it is searched; a variable of that name is not matched.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SEARCHED = ("README.md", "docs", "fence_sorter", "test")
SUFFIXES = {".md", ".py", ".txt", ".json", ".yaml", ".yml", ".csv", ".cfg", ".toml"}

#: Technical phrases that contain a searched word; stripped from a line before the search.
LEGITIMATE = re.compile(
    r"session/process group|scope=\"session\"|start_new_session|new session|session leader"
    r"|\bsessions? of (?:its|their) own\b|\bown session\b|\bprocess session\b"
    r"|\bhelper (?:function|method|class|module|process|thread)s?\b",
    re.IGNORECASE,
)

#: (what it is, pattern) of words that speak of how the project was made.
FORBIDDEN = (
    (
        "a work session",
        re.compile(
            r"\bsessions?\s+\d|\bsession\s+(?:start|end)\b"
            r"|\b(?:this|that|previous|next|last|later|earlier|each|every|one) sessions?\b"
            r"|\b(?:at|until|since|before|after|during) (?:the )?session\b"
            r"|\b(?:of|in) (?:a|the) session\b",
            re.IGNORECASE,
        ),
    ),
    ("an engineer or agent", re.compile(r"\b(?:engineers?|agents?)\b", re.IGNORECASE)),
    ("a person by number", re.compile(r"\bH[1-9]\b")),
    ("a helper as a person", re.compile(r"\bhelper's\b|\bhelpers'", re.IGNORECASE)),
    (
        "a helper as a person",
        re.compile(r"\b(?:a|another|one|each|the other) helper\b", re.IGNORECASE),
    ),
    ("the lead as a person", re.compile(r"\bthe lead(?:'s)?\b(?!\s+time)", re.IGNORECASE)),
    ("a scratch script", re.compile(r"/tmp/\S*\.py\b|`/tmp` script", re.IGNORECASE)),
)


def searched_files() -> list[Path]:
    """Every text file the test searches, this file excepted (it names the words)."""
    files: list[Path] = []
    for name in SEARCHED:
        path = ROOT / name
        found = [path] if path.is_file() else sorted(path.rglob("*"))
        files += [
            f
            for f in found
            if f.is_file()
            and f.suffix in SUFFIXES
            and "__pycache__" not in f.parts
            and "node_modules" not in f.parts  # installed npm packages, not ours
            and f.resolve() != Path(__file__).resolve()
        ]
    return files


def offending_lines(text: str) -> list[tuple[int, str, str]]:
    """(line number, what, line) of every line of ``text`` with a forbidden word."""
    hits = []
    for number, line in enumerate(text.splitlines(), start=1):
        cleaned = LEGITIMATE.sub(" ", line)
        for what, pattern in FORBIDDEN:
            if pattern.search(cleaned):
                hits.append((number, what, line.strip()))
                break
    return hits


@pytest.mark.parametrize(
    "text",
    [
        "measured in session 8 by H1",
        "at session start (ef900a9) the bench gave 0.49 ms",
        "6x in docs/reports/benchmarks.md before this session",
        "the machine shared with a helper's benchmarks",
        "the lead's run on a quiet machine decides",
        "counted by `/tmp/s8/h3_count.py`",
        "two other agents' CPU-bound jobs",
    ],
)
def test_the_patterns_catch_lab_notebook_lines(text: str) -> None:
    assert offending_lines(text)


@pytest.mark.parametrize(
    "text",
    [
        "every node runs in its own session/process group",
        "fence-sorter run in a session of its own (as in a terminal)",
        "session = _session(args, name); session.close()",
        '@pytest.fixture(scope="session")',
        "subprocess.Popen(cmd, start_new_session=True)",
        "a helper function of the reader",
        "h1 = 0.08 m, the fence root thickness",
        "the lead time of a command; min lead 3.40 s",
        "fence-sorter analyze bags/x --out /tmp/ex",
    ],
)
def test_technical_uses_of_the_same_words_pass(text: str) -> None:
    assert offending_lines(text) == []


def test_no_document_code_or_test_speaks_of_how_the_project_was_made() -> None:
    files = searched_files()
    assert any(f.name == "README.md" for f in files) and len(files) > 100
    report = [
        f"{f.relative_to(ROOT)}:{n}: {what}: {line}"
        for f in files
        for n, what, line in offending_lines(f.read_text(encoding="utf-8", errors="replace"))
    ]
    assert not report, "lines that speak of how the project was made:\n" + "\n".join(report)
