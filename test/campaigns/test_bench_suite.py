"""bench-suite writes only its own section of docs/reports/benchmarks.md; lost-message
arithmetic; bad options are exit 2 naming them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from processes import run_cli

from benchmarks.bench_suite import (
    BEGIN,
    END,
    lost,
    message_counts,
    stream_sim_span,
    unpaced_rtf,
    write_json,
    write_section,
)
from fence_sorter.runner.monitor import Records


def test_section_is_appended_then_replaced_in_place(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    doc.write_text("# Benchmarks\n\nhand-written tables\n")
    write_section(doc, f"{BEGIN}\nfirst\n{END}")
    assert doc.read_text() == f"# Benchmarks\n\nhand-written tables\n\n{BEGIN}\nfirst\n{END}\n"
    doc.write_text(doc.read_text() + "\n## after\nmore hand-written text\n")
    write_section(doc, f"{BEGIN}\nsecond\n{END}")
    text = doc.read_text()
    assert "first" not in text and text.count(BEGIN) == 1
    assert text.startswith("# Benchmarks\n\nhand-written tables\n\n" + BEGIN + "\nsecond\n" + END)
    assert text.endswith("## after\nmore hand-written text\n")


def test_lost_messages_counts_every_subscriber_short() -> None:
    summary = {
        "simulator": {
            "parcels_received": "10",
            "commands_received": "4",
            "outcomes.SORTED": "4",
            "outcomes.NOT_DIVERTED": "6",
        },
        "controller": {"parcels_received": "9", "commands": "5"},
        "scanner": {"parcels_published": "10"},
        "parcel_messages": 10,
        "command_messages": 5,
        "outcome_messages": 10,
    }
    counts = message_counts(summary)
    assert counts["/sort_outcomes"]["published (simulator)"] == 10
    assert lost(counts) == 2  # one parcel missing at the controller, one command at the simulator


def test_unpaced_rtf_counts_the_stream_not_the_empty_belt_around_it() -> None:
    """Heartbeats each wall second: 200 s of empty belt in the first second, the stream from
    sim 200.5 s to its last outcome at 262 s at 25x, then 100 s of empty belt in a second
    while the run stops its nodes."""
    rec = Records()
    sims = [0.1, 200.0, 225.0, 250.0, 275.0, 375.0]
    rec.diagnostics_history["fence_sorter/simulator"] = [
        {"_wall": str(w), "sim_time_s": str(s)} for w, s in enumerate(sims)
    ]
    rec.parcels = {1: {"scan_time": 200.5}, 2: {"scan_time": 201.7}}
    rec.outcomes = {1: {"time": 206.0}, 2: {"time": 262.0}}
    assert unpaced_rtf(rec) == 25.0
    assert stream_sim_span(rec) == 262.0 - 200.5
    rec.parcels, rec.outcomes = {}, {}  # nothing seen: the whole run
    assert unpaced_rtf(rec) == (375.0 - 0.1) / 5


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "named"),
    [
        (("bench-suite", "--duration", "-5", "--no-write"), "--duration must be in (0, inf)"),
        (("bench-suite", "--param", "physics_rate=500", "--no-write"), "must be NODE:KEY=VALUE"),
    ],
)
def test_bad_input_exits_2_naming_it(args, named):
    done = run_cli(*args, timeout=120, module="benchmarks")
    assert done.returncode == 2, done.stderr
    assert named in done.stderr
    assert "Traceback" not in done.stderr


def test_json_keeps_the_run_with_and_the_run_without_rrd_side_by_side(tmp_path: Path) -> None:
    out = tmp_path / "bench-suite.json"
    write_json(out, {"rrd": False, "deadline_misses": 3.0}, "bench-suite", "abc1234")
    write_json(out, {"rrd": True, "deadline_misses": 5.0}, "bench-suite --rrd", "abc1234")
    write_json(out, {"rrd": False, "deadline_misses": 4.0}, "bench-suite", "def5678")
    runs = json.loads(out.read_text())["runs"]
    assert sorted(runs) == ["plain", "rrd"]
    assert runs["plain"]["deadline_misses"] == 4.0 and runs["plain"]["commit"] == "def5678"
    assert runs["rrd"]["deadline_misses"] == 5.0 and runs["rrd"]["command"] == "bench-suite --rrd"
