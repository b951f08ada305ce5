"""The generated reports are their data: the committed markdown's tables are the ones the
committed JSON renders to, so a report cannot drift from its figures (or be edited by hand)."""

from __future__ import annotations

import json
from pathlib import Path

from fence_sorter.verification import accuracy, stability
from fence_sorter.verification.report import fmt, table, tables

DOCS = Path(__file__).resolve().parents[2] / "docs"


def test_table_helpers() -> None:
    assert table(["a", "b"], [[1, "x"], ["", 2.5]]) == [
        "| a | b |",
        "|---|---|",
        "| 1 | x |",
        "|  | 2.5 |",
    ]
    text = "intro\n| a |\n|---|\n| 1 |\n\ntext\n| b |\n|---|\n"
    assert tables(text) == [["| a |", "|---|", "| 1 |"], ["| b |", "|---|"]]
    assert fmt(float("nan")) == fmt(None) == "n/a" and fmt(1.5e-3) == "1.50e-03"


def test_accuracy_readme_tables_are_those_of_its_results_json() -> None:
    data = json.loads((DOCS / "accuracy" / "results.json").read_text(encoding="utf-8"))
    committed = tables((DOCS / "accuracy" / "README.md").read_text(encoding="utf-8"))
    rendered = tables(accuracy.render_readme(data))
    # every scene's run table and summary, the reference checks, settings and machine
    assert len(rendered) >= 3 * len(data["scenes"]) + 2
    assert committed == rendered


def test_accuracy_summary_is_computed_from_the_runs() -> None:
    """The summary's figures follow from the points: the default's row is the default run's."""
    data = json.loads((DOCS / "accuracy" / "results.json").read_text(encoding="utf-8"))
    sc = data["scenes"][0]
    points, ref, ms = accuracy.scene_data(sc)
    rows = dict(accuracy.summary(points, ref, ms))
    (default,) = [p for p in sc["points"] if p["is_default"]]
    assert rows["default: wall, RTF"].startswith(f"{default['wall'] * 1e3:.1f} ms")
    assert rows["default: peak-force, trajectory, final-pose error"].startswith(
        f"{default['errors']['peak_force']:.2e}"
    )


def test_stability_readme_tables_are_those_of_its_results_json() -> None:
    data = json.loads((DOCS / "stability" / "results.json").read_text(encoding="utf-8"))
    committed = tables((DOCS / "stability" / "README.md").read_text(encoding="utf-8"))
    (rendered,) = tables(stability.render_readme(data))
    assert len(rendered) == 2 + len(data["cases"])  # one row per case
    assert committed == [rendered]
