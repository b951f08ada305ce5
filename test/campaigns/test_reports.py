"""The generated reports are their data: the committed markdown's tables are the ones the
committed JSON renders to, so a report cannot drift from its figures (or be edited by hand)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks import bench, convergence, dt_max, faults, imports, startup, versus
from benchmarks.sections import section_of
from fence_sorter.verification import accuracy, stability_random, stability_report
from fence_sorter.verification.report import fmt, table, tables

DOCS = Path(__file__).resolve().parents[2] / "docs" / "reports"


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


def test_random_stability_tables_are_those_of_its_json() -> None:
    data = json.loads((DOCS / "stability" / "random.json").read_text(encoding="utf-8"))
    committed = tables((DOCS / "stability" / "random.md").read_text(encoding="utf-8"))
    rendered = tables(stability_random.render_markdown(data))
    # the space, the results, and per failing cause its bounds and its events
    assert len(rendered) == 2 + 2 * len(data["summary"]["regions"])
    assert committed == rendered


def test_stability_readme_tables_are_those_of_its_results_json() -> None:
    data = json.loads((DOCS / "stability" / "results.json").read_text(encoding="utf-8"))
    committed = tables((DOCS / "stability" / "README.md").read_text(encoding="utf-8"))
    (rendered,) = tables(stability_report.render_readme(data))
    assert len(rendered) == 2 + len(data["cases"])  # one row per case
    assert committed == [rendered]


DATA = Path(__file__).resolve().parent / "data"

#: the tables docs/reports/benchmarks.md gets from data/bench_small.json, written out by hand
BENCH_SMALL_TABLES = [
    [
        "|  |  |",
        "|---|---|",
        "| cpu | Test CPU |",
        "| cores | 2 |",
        "| load average (1, 5, 15 min) | 0.10 0.20 0.30 before, 1.00 1.10 1.20 after |",
    ],
    [
        "| target | scene | measured | limit | verdict | note |",
        "|---|---|---|---|---|---|",
        "| stiff-fence event (as loaded) | positioned_stiff | 2.00 ms | <= 5 ms | **PASS** "
        "| median of 3 |",
    ],
    [
        "| scene | method | sim time [s] | wall median [ms] | CPU median [ms] | real-time factor "
        "| real-time factor on CPU time | steps / rejected | peak N [N] | reference peak N [N] "
        "| rel. error | exit speed diff [m/s] | first call in this process [ms] | repeats |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        "| positioned_stiff | adaptive rtol 0.0001 dt_max 0.005 | 0.500 | 2.00 | 1.00 | 250.0 "
        "| 500.0 | 100 / 5 | 100.05 | 100 | 5.0e-04 | 1.0e-05 | 2.00 | 3 |",
    ],
    [
        "| scene | our reference peak N [N] | change at dt / 2 | wall [s] "
        "| SciPy reference peak N [N] | change at rtol / 10 | wall [s] | SciPy ref. vs ours "
        "| the same with conveyor.mu_belt = 0 |",
        "|---|---|---|---|---|---|---|---|---|",
        "| positioned_stiff | 100 | 1.0e-06 | 0.3 | 100.002 | 0.0e+00 | 3.0 | 2.0e-05 | not run |",
    ],
    [
        "| scene | error vs | same error | method | loosest rung reaching it | its error "
        "| error at the next tighter rung | steps | wall median [ms] | wall / default's |",
        "|---|---|---|---|---|---|---|---|---|---|",
        "| positioned_stiff | SciPy ref. | <= 5.0e-04 | **scipy:LSODA** | rtol 0.001 | 8.0e-05 "
        "| 1.0e-05 | 400 | 50.00 | 25x |",
        "| positioned_stiff | our ref. | <= 5.0e-04 | **scipy:LSODA** | rtol 0.001 | 1.0e-04 "
        "| 2.0e-05 | 400 | 50.00 | 25x |",
    ],
    [
        "| scene | method | rtol | wall [s] | steps | error vs our ref. | error vs SciPy ref. "
        "| status |",
        "|---|---|---|---|---|---|---|---|",
        "| positioned_stiff | scipy:LSODA | 0.001 | 0.050 | 400 | 1.0e-04 | 8.0e-05 | ok |",
        "| positioned_stiff | scipy:LSODA | 0.0001 | 0.080 | 800 | 2.0e-05 | 1.0e-05 | ok |",
    ],
    [
        "| scene | ms per event (as loaded) | ms per event (no recording) | steps | sim time [s] "
        "| target |",
        "|---|---|---|---|---|---|",
        "| positioned_stiff | 2.00 | 1.00 | 100 | 0.500 | PASS |",
    ],
    [
        "| scene | tracemalloc peak of one run [KiB] | fresh process max RSS after imports [MiB] "
        "| ... after one event [MiB] |",
        "|---|---|---|---|",
        "| positioned_stiff | 200 | 100 | 150 |",
    ],
    [
        "| scene | variant | same physics | parts vs built | wall median [ms] | / built | steps "
        "| peak N [N] | peak vs built | exit speed [m/s] | sorted |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        "| positioned_stiff | as built | yes | (built) | 2.00 | 1.00 | 100 | 100.05 | 0.0e+00 "
        "| 1.000000 | yes |",
        "| positioned_stiff | no recording | yes | -belt | 1.00 | 0.50 | 100 | 100.05 | 0.0e+00 "
        "| 1.000000 | yes |",
    ],
    [
        "|  | JIT (Numba) | NUMBA_DISABLE_JIT=1 |",
        "|---|---|---|",
        "| wall median [ms] | 1.00 | 100.00 |",
        "| timed calls | 3 | 2 |",
        "| real-time factor | 400.0 | 4.00 |",
        "| peak N [N] | 1000 | 1000 |",
    ],
]


def test_bench_markdown_of_a_small_report_is_the_one_written_by_hand() -> None:
    data = json.loads((DATA / "bench_small.json").read_text(encoding="utf-8"))
    text = bench.render_markdown(bench.report_from_dict(data))
    assert tables(text) == BENCH_SMALL_TABLES
    assert "Without the JIT the same run takes **100x** as long" in text
    assert "peaked at 200 MiB resident" in text


def test_bench_renders_again_from_its_json_keeping_the_suite_section(tmp_path: Path) -> None:
    from benchmarks.bench_suite import BEGIN, END
    from benchmarks.commands import bench as bench_cli

    out = tmp_path / "benchmarks.md"
    out.write_text(f"old\n\n{BEGIN}\n| suite |\n|---|\n{END}\n", encoding="utf-8")
    assert bench_cli.main(["--from-json", str(DATA / "bench_small.json"), "--out", str(out)]) == 0
    assert tables(out.read_text(encoding="utf-8")) == [*BENCH_SMALL_TABLES, ["| suite |", "|---|"]]
    bad = tmp_path / "bad.json"
    bad.write_text("{}", encoding="utf-8")
    assert bench_cli.main(["--from-json", str(bad), "--out", str(out)]) == 2


def without_suite_section(markdown: str) -> str:
    """The markdown ``python -m benchmarks bench`` writes, without the node-suite section
    ``python -m benchmarks bench-suite`` keeps in the same file."""
    from benchmarks.bench_suite import BEGIN, END

    return markdown.replace(section_of(markdown, BEGIN, END), "", 1)


@pytest.mark.skipif(
    not (DOCS / "benchmarks.json").is_file(),
    reason="docs/reports/benchmarks.json not committed yet",
)
def test_benchmarks_md_tables_are_those_of_benchmarks_json() -> None:
    data = json.loads((DOCS / "benchmarks.json").read_text(encoding="utf-8"))
    committed = tables(without_suite_section((DOCS / "benchmarks.md").read_text(encoding="utf-8")))
    rendered = tables(bench.render_markdown(bench.report_from_dict(data)))
    assert len(rendered) >= 8
    assert committed == rendered


def test_reliability_md_is_its_json_rendered() -> None:
    data = json.loads((DOCS / "reliability.json").read_text(encoding="utf-8"))
    committed = (DOCS / "reliability.md").read_text(encoding="utf-8")
    rendered = faults.render_report(data)
    assert len(tables(rendered)) == len(data)  # one table per section
    assert committed == rendered


@pytest.mark.skipif(
    not (DOCS / "versus.json").is_file(), reason="docs/reports/versus.json not written"
)
def test_versus_md_is_its_json_rendered() -> None:
    data = json.loads((DOCS / "versus.json").read_text(encoding="utf-8"))
    assert (DOCS / "versus.md").read_text(encoding="utf-8") == versus.render(data)


def test_startup_readme_is_its_json_rendered() -> None:
    data = json.loads((DOCS / "startup" / "startup.json").read_text(encoding="utf-8"))
    rendered = startup.render(data)
    assert len(tables(rendered)) >= 1
    assert (DOCS / "startup" / "README.md").read_text(encoding="utf-8") == rendered


@pytest.mark.skipif(
    not (DOCS / "calibration.json").is_file(), reason="docs/reports/calibration.json not written"
)
def test_calibration_md_figures_are_its_json_rendered() -> None:
    """docs/reports/calibration.md's generated section (coverage, per-block counts, per-seed z,
    fresh noise) is what ``calibrate-bench --from-json docs/reports/calibration.json`` renders,
    the machine it names included."""
    from benchmarks import calibrate_bench as calibration_bench

    data = json.loads((DOCS / "calibration.json").read_text(encoding="utf-8"))
    doc = (DOCS / "calibration.md").read_text(encoding="utf-8")
    section = section_of(doc, calibration_bench.BEGIN, calibration_bench.END)
    rendered = calibration_bench.render(data, data["command"], data["commit"])
    assert len(tables(rendered)) >= 2
    assert section == rendered


def test_numerics_convergence_section_is_its_json_rendered() -> None:
    """The convergence section of docs/design/numerics.md is docs/reports/convergence.json
    rendered, and its figures are the points' own: one row per scene, a cell per rtol."""
    data = json.loads((DOCS / "convergence.json").read_text(encoding="utf-8"))
    doc = (DOCS.parent / "design" / "numerics.md").read_text(encoding="utf-8")
    section = section_of(doc, convergence.BEGIN, convergence.END)
    assert section == convergence.render(data)
    (rendered,) = tables(section)
    scenes = {p["scene"] for p in data["points"]}
    assert len(rendered) == 2 + len(scenes) and len(data["points"]) == len(scenes) * len(
        data["rtols"]
    )
    first = data["points"][0]
    assert f"{first['error']:.1e} / {first['steps']} / " in rendered[2]
    assert data["command"].startswith("python -m benchmarks.convergence")
    assert f"at {data['commit']} by `{data['command']}`" in section


def test_imports_section_is_its_json_rendered_and_no_help_loads_a_heavy_module() -> None:
    """docs/design/imports.md's measured section is docs/reports/imports.json rendered, with a
    row per command of the campaign; none of them loaded a heavy dependency (what the section
    and the lazy dispatch of the command line promise)."""
    data = json.loads((DOCS / "imports.json").read_text(encoding="utf-8"))
    doc = (DOCS.parent / "design" / "imports.md").read_text(encoding="utf-8")
    assert section_of(doc, imports.BEGIN, imports.END) == imports.render(data)
    rendered = tables(imports.render(data))[0]
    assert len(rendered) == 2 + len(imports.COMMANDS) == 2 + len(data["commands"])
    assert [c["heavy"] for c in data["commands"]] == [[]] * len(imports.COMMANDS)
    assert all(c["modules"] > 50 and c["wall"] > 0 for c in data["commands"])
    # what the text beside the table says of the modules a node or a scene reader imports
    of = {m["module"].rsplit(".", 1)[1]: m for m in data["modules"]}
    assert len(tables(imports.render(data))) == 2 and len(of) == len(imports.MODULES)
    assert of["scene"]["heavy"] == [] and not of["scene"]["kernel"]
    assert not of["scanner"]["kernel"] and not of["recorder"]["kernel"]
    assert "rclpy" in of["scanner"]["heavy"] and "numba" not in of["recorder"]["heavy"]
    assert of["controller"]["kernel"] and of["simulator"]["kernel"]


def test_numerics_dt_max_section_is_its_json_rendered() -> None:
    """The dt_max section of docs/design/numerics.md is docs/reports/dt_max.json rendered: a
    column per cap, its steps and error those of the JSON's rows."""
    data = json.loads((DOCS / "dt_max.json").read_text(encoding="utf-8"))
    doc = (DOCS.parent / "design" / "numerics.md").read_text(encoding="utf-8")
    assert section_of(doc, dt_max.BEGIN, dt_max.END) == dt_max.render(data)
    (rendered,) = tables(dt_max.render(data))
    assert rendered[0].count("|") == 2 + len(data["rows"])
    cells = rendered[3].split("|")[2:-1]  # steps / rejected
    assert [c.strip() for c in cells] == [f"{r['steps']}/{r['rejected']}" for r in data["rows"]]
