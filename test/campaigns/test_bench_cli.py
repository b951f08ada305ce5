"""``python -m benchmarks bench`` run as a process: --quick writes the markdown report (tables, the
JIT comparison) and the JSON figures; bad arguments exit 2 with one line. No timing assertions:
speed targets live in the benchmark report, never in unit tests. ROS-free."""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks import bench as B
from benchmarks.commands import bench as bench_cli

REPO = Path(__file__).resolve().parents[2]
TIMEOUT = 600.0
SECTIONS = (
    "## Machine",
    "## Targets",
    "## Default configuration per scene",
    "## References",
    "## SciPy baselines at the same error",
    "## Stiff-fence events (optimisation inner loop)",
    "## Peak memory",
    "## Model parts: what each scene leaves out",
    "## Compiled kernel: the same code with and without the JIT",
)


def bench(*args: str) -> subprocess.CompletedProcess:
    """The subcommand on its own (``python -m benchmarks.commands.bench``)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, "-m", "benchmarks.commands.bench", *args],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        cwd=REPO,
        env=env,
    )


def test_register_adds_the_bench_subcommand() -> None:
    parser = argparse.ArgumentParser(prog="bench")
    bench_cli.register(parser)
    args = parser.parse_args(["--quick", "--out", "x.md", "--scenes", "impact_flexible"])
    assert args.func is bench_cli.run
    assert args.quick and args.out == "x.md" and args.scenes == ["impact_flexible"]
    assert parser.parse_args([]).out == "docs/reports/benchmarks.md"


@pytest.mark.slow
def test_quick_writes_the_report(tmp_path: Path) -> None:
    md_path, json_path = tmp_path / "docs" / "benchmarks.md", tmp_path / "bench.json"
    r = bench("--quick", "--out", str(md_path), "--json", str(json_path))
    assert r.returncode == 0, r.stderr
    md = md_path.read_text(encoding="utf-8")
    for section in SECTIONS:
        assert section in md, section
    assert "`python -m benchmarks bench --out " in md and "--quick`" in md
    assert "NUMBA_DISABLE_JIT=1" in md and "| wall median [ms] |" in md
    assert "| positioned_stiff | adaptive " in md
    assert "## Default configuration per scene" in r.stdout  # the report is printed too

    data = json.loads(json_path.read_text(encoding="utf-8"))
    assert data["options"]["quick"] is True
    # the markdown is the JSON rendered: rebuilt from it, the same text
    assert md.startswith(B.render_markdown(B.report_from_dict(data)))
    (s,) = data["scenes"]
    assert s["scene"] == "positioned_stiff"
    d = s["default"]
    out = d["outcome"]
    assert out["success"] and out["sorted"] and out["steps"] > 0
    assert d["method"] == "adaptive" and len(d["walls"]) == 2
    # the default configuration is within the 1e-3 target of a converged reference
    assert s["ours"]["check_change"] < 1e-6
    assert d["error"] < B.TARGET_ERROR
    assert d["wall"] > 0 and d["rtf"] > 0 and d["tracemalloc_peak"] > 0
    # the SciPy ladder ran the quick methods on the quick ladder
    runs = s["baselines"]["runs"]
    assert {r["method"] for r in runs} == set(B.QUICK_SCIPY_METHODS)
    assert {r["rtol"] for r in runs} <= set(B.QUICK_RTOL_LADDER)
    assert s["scipy_ref"]["check_change"] < 1e-4
    # the compiled peers ran the same search, reported first among the speed-up targets
    peer_runs = s["peers"]["runs"]
    assert {r["method"] for r in peer_runs} == set(B.QUICK_PEER_METHODS)
    assert {r["rtol"] for r in peer_runs} <= set(B.QUICK_RTOL_LADDER)
    assert all(r["outcome"]["success"] for r in peer_runs)
    speedups = [t["target"] for t in data["targets"] if t["target"].startswith("speed-up")]
    assert speedups[0].startswith("speed-up vs fastest compiled peer"), speedups
    assert "## Compiled peers at the same error" in md
    assert md.index("## Compiled peers") < md.index("## SciPy baselines")
    for key in ("by_ref", "by_self"):
        comp = s["baselines"][key]
        assert comp["threshold"] in (d["error"], B.TARGET_ERROR)
        if comp["best"] is not None:
            assert comp["best"]["method"] in B.QUICK_SCIPY_METHODS and comp["ratio"] > 0
    # leaving out records and border contact does not change the answer
    variants = s["parts"]["variants"]
    built = variants[0]
    assert built["role"] == "built"
    for v in variants:
        if v["same_physics"]:
            assert v["outcome"]["peak_force"] == built["outcome"]["peak_force"], v["label"]
            assert v["outcome"]["steps"] == built["outcome"]["steps"], v["label"]
    assert any(v["role"] == "full" for v in variants)
    assert "fem_fence" in next(v for v in variants if v["role"] == "full")["parts"]
    # the same code with and without the JIT gives the same answer
    j = data["jit"]
    assert j["jit_child_confirmed"] is True
    assert j["nojit_walls"] and j["jit_walls"]
    assert abs(j["nojit_peak"] - j["jit_peak"]) <= 1e-9 * j["jit_peak"]
    assert s["memory"]["rss_after_run_kib"] > 0
    verdicts = {t["verdict"] for t in data["targets"]}
    assert verdicts <= {"PASS", "FAIL", "N/A"}
    assert any(t["target"].startswith("stiff-fence event") for t in data["targets"])


def test_unknown_scene_is_one_line_naming_the_allowed() -> None:
    r = bench("--scenes", "no_such_scene", "--out", os.devnull)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
    assert "no_such_scene" in lines[0]
    for name in B.SCENES:
        assert name in lines[0]


def test_bad_repeats_exit_2() -> None:
    r = bench("--repeats", "0", "--out", os.devnull)
    assert r.returncode == 2
    assert r.stderr.strip().startswith("benchmarks: error: --repeats")


def test_bench_keeps_the_node_suite_section_of_the_file(tmp_path):
    """``python -m benchmarks bench`` regenerates docs/reports/benchmarks.md but must carry over
    the section ``python -m benchmarks bench-suite`` writes between its markers."""
    from benchmarks.commands.bench import _suite_section

    out = tmp_path / "benchmarks.md"
    assert _suite_section(out) == ""
    out.write_text("# old\n<!-- suite:begin -->\n| rtf | 1.0 |\n<!-- suite:end -->\nold tail\n")
    kept = _suite_section(out)
    assert kept.strip().startswith("<!-- suite:begin -->")
    assert "| rtf | 1.0 |" in kept and "old tail" not in kept and "# old" not in kept


def test_a_rung_that_meets_the_error_by_cancellation_is_not_chosen() -> None:
    """DOP853 on arbitrary_stiff (docs/design/numerics.md): rtol 1e-2 lands within 2.5e-4 of our
    reference by a cancellation of errors, rtol 1e-3 and 1e-4 are off by ~1e-2; rtol 1e-5 and
    1e-6 hold. The loosest *sustained* rung is chosen; a rung whose next one did not run stands."""
    from types import SimpleNamespace

    ok = SimpleNamespace(success=True)
    errors = {1e-2: 2.5e-4, 1e-3: 1.1e-2, 1e-4: 1.3e-2, 1e-5: 4e-4, 1e-6: 1e-5}
    runs = [B.LadderRun("scipy:DOP853", r, r, 0.01, ok, e, e, False) for r, e in errors.items()]
    assert B._loosest(runs, "scipy:DOP853", "ref", 9.5e-4).rtol == 1e-5
    assert B._loosest(runs[:1], "scipy:DOP853", "ref", 9.5e-4).rtol == 1e-2  # next not run


def _fake_rungs(errors: dict[str, dict[float, float]], walls: dict[str, float]):
    """A ``run_rung`` over a table of peak-force errors (both metrics the same) and per-method
    wall times that grow 10 % a rung; it records which rungs were run."""
    from types import SimpleNamespace

    called: list[tuple[str, float]] = []

    def run_rung(method: str, rtol: float):
        called.append((method, rtol))
        e = errors[method][rtol]
        ok = math.isfinite(e)
        wall = walls[method] * 1.1 ** -math.log10(rtol)
        return B.LadderRun(method, rtol, rtol, wall, SimpleNamespace(success=ok), e, e, False)

    return run_rung, called


LADDER = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7)


@pytest.mark.slow
def test_the_fastest_candidate_is_confirmed_at_the_next_rung() -> None:
    """positioned_stiff (docs/reports/accuracy): LSODA meets 3.2e-4 at rtol 1e-3 (8.3e-6)
    but not at 1e-4 (8.2e-4); rtol 1e-5 and tighter hold. RK45 holds from 1e-2 on but is
    slower. The search must run LSODA's 1e-4 rung, go on to 1e-5, confirm it at 1e-6, and the
    choice is LSODA rtol 1e-5, with or without a SciPy reference."""
    errors = {
        "scipy:RK45": {1e-2: 2.4e-5, 1e-3: 1.2e-4, 1e-4: 6.2e-5, 1e-5: 4.3e-5},
        "scipy:LSODA": {1e-2: 8.3e-4, 1e-3: 8.3e-6, 1e-4: 8.2e-4, 1e-5: 1.1e-4, 1e-6: 9e-7},
    }
    run_rung, called = _fake_rungs(errors, {"scipy:RK45": 0.100, "scipy:LSODA": 0.005})
    for gap in (math.inf, 3.5e-6):  # without and with a SciPy reference
        called.clear()
        runs = B.search_rungs(list(errors), LADDER, run_rung, 3.2e-4, gap)
        assert ("scipy:LSODA", 1e-4) in called and ("scipy:LSODA", 1e-6) in called
        # over RETIME_FACTOR x slower: not re-timed, so its candidate is not confirmed
        assert ("scipy:RK45", 1e-3) not in called
        picks = {m: B._loosest(runs, m, "ref", 3.2e-4) for m in errors}
        assert picks["scipy:LSODA"].rtol == 1e-5 and picks["scipy:RK45"].rtol == 1e-2
        assert len(called) == len(set(called))  # no rung run twice


@pytest.mark.slow
def test_every_candidate_that_will_be_re_timed_is_confirmed() -> None:
    """Search runs of RK45 rtol 1e-2 (12 ms) and LSODA rtol 1e-3 (13 ms) within noise of each
    other: confirming only the faster search run would leave LSODA's lucky rung unconfirmed,
    and the re-timed medians would then choose it. Both are
    within RETIME_FACTOR of the fastest, so both must be confirmed."""
    errors = {
        "scipy:RK45": {1e-2: 2.4e-5, 1e-3: 1.2e-4, 1e-4: 6.2e-5},
        "scipy:LSODA": {1e-2: 8.3e-4, 1e-3: 8.3e-6, 1e-4: 8.2e-4, 1e-5: 1.1e-4, 1e-6: 9e-7},
    }
    run_rung, called = _fake_rungs(errors, {"scipy:RK45": 0.0109, "scipy:LSODA": 0.0108})
    runs = B.search_rungs(list(errors), LADDER, run_rung, 3.2e-4, 3.5e-6)
    assert ("scipy:RK45", 1e-3) in called and ("scipy:LSODA", 1e-4) in called
    picks = {m: B._loosest(runs, m, "ref", 3.2e-4) for m in errors}
    assert picks["scipy:LSODA"].rtol == 1e-5 and picks["scipy:RK45"].rtol == 1e-2


@pytest.mark.slow
def test_a_confirmed_fastest_candidate_ends_the_search() -> None:
    """A fastest candidate whose next rung holds ends the search at once; a refuted method
    that never reaches the error again drops out and the next fastest is confirmed."""
    errors = {
        "scipy:LSODA": {1e-2: 1e-5, 1e-3: 2e-5, 1e-4: 1e-5},
        "scipy:BDF": {1e-2: 1e-5, 1e-3: 5e-3, 1e-4: 5e-3, 1e-5: 5e-3, 1e-6: 5e-3, 1e-7: 5e-3},
        "scipy:Radau": {1e-2: 1e-4, 1e-3: 1e-4},
    }
    run_rung, called = _fake_rungs(
        errors, {"scipy:LSODA": 0.009, "scipy:BDF": 0.001, "scipy:Radau": 0.05}
    )
    runs = B.search_rungs(list(errors), LADDER, run_rung, 3e-4, math.inf)
    assert [c for c in called if c[0] == "scipy:LSODA"] == [
        ("scipy:LSODA", 1e-2),
        ("scipy:LSODA", 1e-3),
    ]
    assert len([c for c in called if c[0] == "scipy:BDF"]) == len(LADDER)
    assert B._loosest(runs, "scipy:BDF", "ref", 3e-4) is None
    assert called.count(("scipy:Radau", 1e-3)) == 0
