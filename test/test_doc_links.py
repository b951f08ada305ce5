"""Every relative markdown link of README.md and docs/**/*.md names a file or folder that
exists in the checkout (anchors and web addresses are not followed)."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCUMENTS = sorted([REPO / "README.md", *(REPO / "docs").rglob("*.md")])
#: [text](target) and ![alt](target); a target ends at the first space or ")"
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)


def relative_links(text: str) -> list[str]:
    """The relative link targets of a markdown text, code blocks and inline code left out."""
    text = FENCE.sub("", text)
    text = re.sub(r"`[^`\n]*`", "", text)
    found = []
    for target in LINK.findall(text):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue  # https:, mailto:, an anchor of the same page
        found.append(target.split("#", 1)[0])
    return found


def test_the_link_reader_finds_relative_links_only():
    text = (
        "See [a](design/a.md#x), ![b](img/b.png), [c](https://x.org/c.md), [d](#local),\n"
        '`[e](not/a/link.md)`\n```\n[f](in/code.md)\n```\n[g](../g/ "title")'
    )
    assert relative_links(text) == ["design/a.md", "img/b.png", "../g/"]


def test_there_are_documents_and_links():
    assert len(DOCUMENTS) > 20
    assert sum(len(relative_links(d.read_text())) for d in DOCUMENTS) > 50


@pytest.mark.parametrize("doc", DOCUMENTS, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(doc):
    broken = [
        t for t in relative_links(doc.read_text()) if not (doc.parent / t).resolve().exists()
    ]
    assert not broken, f"{doc.relative_to(REPO)}: links to missing files: {broken}"
