"""The marked section of a document: found, replaced with the rest kept, appended on request."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.sections import framed, has_section, replace_section, section_of

B, E = "<!-- x:begin -->", "<!-- x:end -->"


def test_the_section_is_replaced_and_the_rest_kept(tmp_path: Path) -> None:
    doc = tmp_path / "d.md"
    doc.write_text(f"{E} head\n{B}\nold\n{E}\ntail {E}\n", encoding="utf-8")
    replace_section(doc, f"{B}\nnew\n{E}", B, E)
    assert doc.read_text(encoding="utf-8") == f"{E} head\n{B}\nnew\n{E}\ntail {E}\n"
    assert section_of(doc.read_text(encoding="utf-8"), B, E) == f"{B}\nnew\n{E}"


def test_without_the_marks_it_appends_on_request_or_refuses(tmp_path: Path) -> None:
    doc = tmp_path / "d.md"
    doc.write_text(f"head\n{E} before {B}\n", encoding="utf-8")  # no end after the begin
    assert not has_section(doc.read_text(encoding="utf-8"), B, E)
    assert section_of(doc.read_text(encoding="utf-8"), B, E) == ""
    with pytest.raises(ValueError, match="no section between"):
        replace_section(doc, f"{B}\n{E}", B, E)
    replace_section(doc, f"{B}\nnew\n{E}", B, E, append=True)
    assert doc.read_text(encoding="utf-8") == f"head\n{E} before {B}\n\n{B}\nnew\n{E}\n"
    fresh = tmp_path / "new.md"
    replace_section(fresh, f"{B}\n{E}", B, E, append=True)
    assert fresh.read_text(encoding="utf-8") == f"{B}\n{E}\n"


def test_a_framed_section_names_its_command_and_source_and_is_found_again() -> None:
    text = framed(B, E, "docs/reports/x.json", "python -m benchmarks.x --n 2", ["| a |", "|---|"])
    assert text.splitlines() == [
        B,
        "<!-- written by `python -m benchmarks.x --n 2` from docs/reports/x.json; "
        "do not edit by hand -->",
        "",
        "| a |",
        "|---|",
        "",
        E,
    ]
    assert section_of(f"intro\n{text}\nrest", B, E) == text
