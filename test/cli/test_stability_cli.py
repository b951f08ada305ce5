"""``fence-sorter stability`` run as a process: --quick writes the report (README table,
results.json, summary.png); exit codes 0 / 1 / 2. ROS-free (python -m fence_sorter.cli.main)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from processes import run_cli

from fence_sorter.verification import stability_cases as C

REPO = Path(__file__).resolve().parents[2]
TIMEOUT = 600.0
TABLE_HEADER = "| case | description | expected | verdict |"


def fence_sorter(*args: str) -> subprocess.CompletedProcess:
    return run_cli(*args, timeout=TIMEOUT)


@pytest.mark.slow
def test_quick_writes_the_report(tmp_path: Path) -> None:
    out = tmp_path / "stability"
    r = fence_sorter("stability", "--quick", "--out", str(out))
    # 0: every case met its expectation; 1: some did not, and they are named
    assert r.returncode in (0, 1), r.stderr
    readme = (out / "README.md").read_text(encoding="utf-8")
    assert TABLE_HEADER in readme
    assert "fence-sorter stability" in readme and "--quick" in readme
    rows = [line for line in readme.splitlines() if line.startswith("| `")]
    fast = [c.name for c in C.fast_cases()]
    assert [row.split("`")[1] for row in rows] == fast
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert [c["name"] for c in data["cases"]] == fast
    assert (out / "summary.png").stat().st_size > 10_000
    unmet = [c["name"] for c in data["cases"] if not c["meets_expectation"]]
    if unmet:
        assert r.returncode == 1
        assert "did not meet their expectation: " + ", ".join(unmet) in r.stdout
    else:
        assert r.returncode == 0
    for c in data["cases"]:
        assert c["verdict"] in ("PASS", "DIAGNOSED", "FAIL")
    by_name = {c["name"]: c for c in data["cases"]}
    assert by_name["diverging_trapezoidal"]["verdict"] == "DIAGNOSED"
    assert "min_dt" in by_name["diverging_trapezoidal"]["diagnosis"]
    assert any("outside the paper's range" in w for w in by_name["belt_5"]["warnings"])


@pytest.mark.slow
def test_selected_cases_exit_zero(tmp_path: Path) -> None:
    r = fence_sorter(
        "stability", "--cases", "mass_1,diverging_trapezoidal", "--out", str(tmp_path)
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "every case met its expectation" in r.stdout
    readme = (tmp_path / "README.md").read_text(encoding="utf-8")
    assert "| `mass_1` |" in readme and "| `diverging_trapezoidal` |" in readme


@pytest.mark.slow
def test_unknown_case_exits_2() -> None:
    r = fence_sorter("stability", "--cases", "mass_1", "no_such_case")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
    assert lines[0].startswith("fence-sorter: error: unknown stability case no_such_case")
    assert "allowed: " in lines[0] and "mass_1" in lines[0] and "grazing_exact" in lines[0]


@pytest.mark.slow
def test_quick_and_cases_are_exclusive() -> None:
    r = fence_sorter("stability", "--quick", "--cases", "mass_1")
    assert r.returncode == 2 and "not allowed with argument" in r.stderr


@pytest.mark.slow
def test_list() -> None:
    r = fence_sorter("stability", "--list")
    assert r.returncode == 0
    assert [line.split()[0] for line in r.stdout.splitlines()] == C.case_names()
