"""The user guides and the README describe the product, not its history; docs cite the paper.

A guide (docs/guide/*.md) or the README that names a commit (as `git log --oneline` prints it:
7-40 hexadecimal characters with a digit and a letter, or 7 digits after "at" or "commit") or
a tracker entry ("issue 5", "the issue's") narrates how the project was made; the generated
reports in docs/reports/ carry the commit a figure was measured at, the guides point to them.
No document under docs/ nor the README cites the paper by a path outside the repository
(shared/docs/...): by title and authors.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: a commit as git abbreviates it: 7-40 hex characters, at least one digit and one of a-f,
#: not a colour (#rrggbbaa), a literal (0x...), part of a longer word or of a number
COMMIT = re.compile(r"(?<![#\w])(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}(?!\w)")
#: an abbreviated commit of digits only, as "at 1937645" or "commit 1937645"
DIGITS_COMMIT = re.compile(r"\b(?:at|commit)\s+\d{7}(?![\w.,]?\d)(?!\w)")
#: a tracker entry: "issue 5", "issue-5", "issue #5", "issues 5 and 7", "the issue's"
ISSUE = re.compile(r"\bissues?[ -]?#?\d+|\bthe issue's\b", re.IGNORECASE)
OUTSIDE_PATH = re.compile(r"shared/docs\b")


def guides() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]


def history_words(text: str) -> list[str]:
    """Every commit and tracker entry ``text`` names."""
    return [m.group(0) for p in (COMMIT, DIGITS_COMMIT, ISSUE) for m in p.finditer(text)]


@pytest.mark.parametrize(
    "text",
    [
        "measured at 46b9146 on 2 cores",
        "(at dbc8103 and 332488d, load 3)",
        "32.1x at 1937645 and 22.9x",
        "at 87e6ba9-9cff254 on this VM",
        "the full commit 5417aad0c3e2b9f1d4a6e8c7b5a3d1f0e2c4b6a8",
        "Neither meets the issue-5 pacing targets",
        "the node suite (issue 5)",
        "the issue's 20 seeds",
    ],
)
def test_the_patterns_catch_commits_and_tracker_entries(text: str) -> None:
    assert history_words(text)


@pytest.mark.parametrize(
    "text",
    [
        "colour #ff8800aa for the fence",
        "opcode 0x02 and 0xdeadbeef",
        "1283x (0.94 ms per event), 1e-5 and 2400 pcs/h",
        "seed 20260101 and 1234567 parcels, at 1234567.5 s, at 12345678",
        "names like fence_sorter_a1b2c3d and a1b2c3d4e_x",
        "decade, facade, deadbeef",
        "see https://github.com/foxglove/ros-foxglove-bridge/issues/382",
    ],
)
def test_colours_numbers_and_words_pass(text: str) -> None:
    assert history_words(text) == []


def test_guides_and_readme_name_no_commit_nor_tracker_entry() -> None:
    files = guides()
    assert len(files) >= 8
    hits = [
        f"{f.relative_to(ROOT)}:{n}: {word}"
        for f in files
        for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), start=1)
        for word in history_words(line)
    ]
    assert not hits, "guides narrate history (the reports carry the commit):\n" + "\n".join(hits)


def test_docs_cite_the_paper_not_a_path_outside_the_repository() -> None:
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    hits = [
        f"{f.relative_to(ROOT)}:{n}"
        for f in files
        for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), start=1)
        if OUTSIDE_PATH.search(line)
    ]
    assert not hits, "cite the paper by title and authors, not shared/docs:\n" + "\n".join(hits)
