"""docs/startup/README.md is what its startup.json renders to (``verification.startup``)."""

from __future__ import annotations

import json
from pathlib import Path

from fence_sorter.verification import startup

DOCS = Path(__file__).resolve().parents[2] / "docs" / "startup"


def test_startup_readme_is_its_json() -> None:
    data = json.loads((DOCS / "startup.json").read_text(encoding="utf-8"))
    assert (DOCS / "README.md").read_text(encoding="utf-8") == startup.render(data)
    assert [s["scene"] for s in data["scenes"]] and set(data["parts"]) == set(startup.PARTS)
