"""The fault campaign's command-line table (benchmarks.faults): a bad stream,
a bad scene and a bad option each exit 2 with one line, and the report says so."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import faults as F

pytestmark = pytest.mark.faults


def test_bad_input_cases_exit_2_with_one_line_and_are_reported(tmp_path: Path) -> None:
    wanted = {"mu_fence 5", "scene is a list", "--parcels 0"}
    cases = [c for c in F.cli_cases() if c.name in wanted]
    assert len(cases) == 3 and len(F.cli_cases()) >= 30
    results = [F.run_cli_case(c, tmp_path) for c in cases]
    for r in results:
        assert r.ok and r.code == 2 and not r.traceback, r
    by_name = {r.case.name: r for r in results}
    assert "mu_fence must be in [0, 2]" in by_name["mu_fence 5"].line
    assert "--parcels must be in [1, inf)" in by_name["--parcels 0"].line
    meta = {"command": "python -m benchmarks faults --cases cli", "commit": "x", "date": "d"}
    out = tmp_path / "reliability.md"
    data = {"cli": {"rows": [F.cli_row(r) for r in results], "meta": {**meta, "machine": "m"}}}
    data["cli"]["meta"]["wall_s"] = 1.0
    F.write_report(out, data)
    text = out.read_text()
    assert F.verdicts(data) == {"cli": True}
    assert "**3 of 3 as required; tracebacks: 0; silently accepted (exit 0): 0.**" in text
    assert "| streams | mu_fence 5 |" in text
