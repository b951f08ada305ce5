"""The front door stays a front door and the code map stays a map of the code.

README.md is at most 150 lines (what it is, the two commands, what a run shows, the main
commands, links; the rest belongs in docs/), and the code map of docs/design/architecture.md
names every folder of the package, so a new folder cannot appear without its owner and what
it may import.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
README_MAX_LINES = 150


def test_readme_is_at_most_150_lines() -> None:
    lines = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines"


def code_map_entries(markdown: str) -> set[str]:
    """The names in code spans of the first column of the "## Code map" table."""
    section = markdown.split("## Code map", 1)[1].split("\n## ", 1)[0]
    names: set[str] = set()
    for line in section.splitlines():
        if line.startswith("|"):
            first = line.split("|")[1]
            names.update(n.rstrip("/") for n in re.findall(r"`([^`]+)`", first))
    return names


def test_code_map_names_every_folder_of_the_package() -> None:
    entries = code_map_entries(
        (REPO / "docs" / "design" / "architecture.md").read_text(encoding="utf-8")
    )
    folders = {
        p.name
        for p in (REPO / "fence_sorter").iterdir()
        if p.is_dir() and (p / "__init__.py").is_file()
    }
    assert len(folders) >= 10
    missing = sorted(folders - entries)
    assert missing == [], f"docs/design/architecture.md's code map does not name {missing}"
    stale = sorted(e for e in entries - folders if not (REPO / "fence_sorter" / e).exists())
    stale = [e for e in stale if not (REPO / e).exists()]  # benchmarks/, test/ beside it
    assert stale == [], f"the code map names what is not there: {stale}"


def test_code_map_reader_takes_the_first_column() -> None:
    text = (
        "## Code map\n\n| folder | owns |\n|---|---|\n| `a/`, `b.py` | `c/` |\n\n## Next\n| `d/` |"
    )
    assert code_map_entries(text) == {"a", "b.py"}
