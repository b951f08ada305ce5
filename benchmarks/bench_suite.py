"""The node suite's benchmark against its targets: paced run at rtf 1.0 for 60 s at 2400 pcs/h,
and the unpaced simulator's achieved real-time factor, from the nodes' own diagnostics.

Paced: deadline-miss share and cycle lateness p99 / p99.9 (simulator), lost messages on the
reliable topics (published vs received counts of each node and of the run's monitor), the
controller's parcel -> command latency p99, and whether every command arrived before its
parcel's front reached R_s. Unpaced (rtf 0): sim time over wall time between the simulator's
heartbeats around the stream (first scan to last outcome), with all topics published.

:func:`write_section` replaces only the part of docs/reports/benchmarks.md between the suite
markers (the rest of that file is `python -m benchmarks bench`'s); :func:`write_json` keeps the
figures of a run with and one without ``--rrd`` side by side in one JSON file.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

from benchmarks.sections import replace_section
from benchmarks.stall_probe import StallReport, run_probe
from fence_sorter.recording import topics
from fence_sorter.runner.job import RunOptions, run_job

#: length of each host stall probe around the paced run [s of busy time]
PROBE_S = 10.0

BEGIN, END = "<!-- suite:begin -->", "<!-- suite:end -->"
TARGETS = {
    "deadline_miss_share": 0.001,
    "lateness_p99_ms": 0.5,
    "lateness_p99_9_ms": 2.0,
    "controller_p99_ms": 50.0,
    "unpaced_rtf": 20.0,
}


def _num(d: dict, key: str) -> float:
    try:
        return float(d.get(key, "nan"))
    except ValueError:
        return math.nan


def message_counts(summary: dict) -> dict[str, dict[str, int]]:
    """Published vs received per reliable topic, from the nodes' counters and the monitor."""
    sim, ctl, scn = summary["simulator"], summary["controller"], summary["scanner"]

    def i(d: dict, k: str) -> int:
        v = _num(d, k)
        return -1 if math.isnan(v) else int(v)

    outcomes_published = sum(
        int(v) for k, v in sim.items() if k.startswith("outcomes.") and v.isdigit()
    )
    return {
        topics.PARCELS: {
            "published (scanner)": i(scn, "parcels_published"),
            "received (simulator)": i(sim, "parcels_received"),
            "received (controller)": i(ctl, "parcels_received"),
            "received (monitor)": summary["parcel_messages"],
        },
        topics.FENCE_COMMANDS: {
            "published (controller)": i(ctl, "commands"),
            "received (simulator)": i(sim, "commands_received"),
            "received (monitor)": summary["command_messages"],
        },
        topics.SORT_OUTCOMES: {
            "published (simulator)": outcomes_published,
            "received (monitor)": summary["outcome_messages"],
        },
    }


def lost(counts: dict[str, dict[str, int]]) -> int:
    """Messages published on a topic but missing at some subscriber."""
    total = 0
    for c in counts.values():
        pub = next(v for k, v in c.items() if k.startswith("published"))
        total += sum(max(pub - v, 0) for k, v in c.items() if k.startswith("received"))
    return total


def unpaced_rtf(records) -> float:
    """Sim time over wall time between the simulator's heartbeats around the stream: from
    the last one before the first parcel's scan time to the first one after the last
    outcome. The empty belt before the stream and after it (the run stopping its nodes)
    costs the line nothing and would inflate the figure."""
    hist = [
        h for h in records.diagnostics_history.get("fence_sorter/simulator", []) if "_wall" in h
    ]
    start, end = _stream_bounds(records)
    sims = [_num(h, "sim_time_s") for h in hist]
    first = max((i for i, t in enumerate(sims) if t <= start), default=0)
    last = min((i for i, t in enumerate(sims) if t >= end), default=len(hist) - 1)
    if last - first < 1:
        return math.nan
    d_sim = sims[last] - sims[first]
    d_wall = _num(hist[last], "_wall") - _num(hist[first], "_wall")
    return d_sim / d_wall if d_wall > 0 else math.nan


def _stream_bounds(records) -> tuple[float, float]:
    """Sim time of the first parcel's scan and of the last outcome (-inf / inf if none)."""
    scans = [p["scan_time"] for p in records.parcels.values()]
    ends = [o["time"] for o in records.outcomes.values()]
    return (min(scans) if scans else -math.inf), (max(ends) if ends else math.inf)


def stream_sim_span(records) -> float:
    """Sim time from the first parcel's scan to the last outcome [s] (NaN without both)."""
    start, end = _stream_bounds(records)
    return end - start if math.isfinite(start) and math.isfinite(end) else math.nan


def run_bench(
    duration: float = 60.0,
    unpaced_parcels: int = 40,
    say=print,
    params: Sequence[str] = (),
    rrd: bool = False,
) -> dict:
    """Both runs; returns the figures (and the raw summaries). ``params`` (NODE:KEY=VALUE)
    apply to both runs; ``rrd`` makes both runs save a Rerun recording (deleted after)."""
    load0 = os.getloadavg()
    wall0 = time.time()
    probes = [run_probe(PROBE_S)]  # the host's own stalls, before and after the paced run
    with tempfile.TemporaryDirectory(prefix="bench_suite_") as tmp:
        rrd_file = str(Path(tmp) / "paced.rrd") if rrd else None
        paced = run_job(
            RunOptions(duration=duration, rtf=1.0, params=list(params), rrd=rrd_file), say=say
        )
    probes.append(run_probe(PROBE_S))
    s = paced.summary
    sim, ctl = s["simulator"], s["controller"]
    cycles = _num(sim, "cycles")
    counts = message_counts(s)
    fig = {
        "paced_exit": paced.code,
        "paced_message": paced.message,
        "parcels": s["parcels_seen"],
        "sorted_divert": s["sorted_divert"],
        "divert": s["divert"],
        "by_reason": s["by_reason"],
        "cycles": cycles,
        "deadline_misses": _num(sim, "deadline_misses"),
        "deadline_miss_share": _num(sim, "deadline_misses") / cycles if cycles else math.nan,
        "lateness_p50_ms": _num(sim, "cycle_lateness_p50_ms"),
        "lateness_p99_ms": _num(sim, "cycle_lateness_p99_ms"),
        "lateness_p99_9_ms": _num(sim, "cycle_lateness_p99_9_ms"),
        "lateness_max_ms": _num(sim, "cycle_lateness_max_ms"),
        "work_p99_ms": _num(sim, "cycle_work_p99_ms"),
        "publish_lag_p99_ms": _num(sim, "publish_lag_p99_ms"),
        "publish_lag_max_ms": _num(sim, "publish_lag_max_ms"),
        "paced_rtf": _num(sim, "real_time_factor_achieved"),
        "counts": counts,
        "lost_messages": lost(counts),
        "controller_p50_ms": _num(ctl, "latency_p50_ms"),
        "controller_p99_ms": _num(ctl, "latency_p99_ms"),
        "controller_max_ms": _num(ctl, "latency_max_ms"),
        "commands": s["commands"],
        "commands_late_monitor": s["commands_late"],
        "commands_late_simulator": int(_num(sim, "commands_late"))
        if not math.isnan(_num(sim, "commands_late"))
        else 0,
        "min_lead_s": s["command_min_lead_s"],
        "paced_wall_s": s["wall_time_s"],
        "duration": duration,
        "unpaced_parcels": unpaced_parcels,
        "params": list(params),
        "rrd": rrd,
        "probes": [asdict(p) for p in probes],
    }
    with tempfile.TemporaryDirectory(prefix="bench_suite_") as tmp:
        rrd_file = str(Path(tmp) / "unpaced.rrd") if rrd else None
        unpaced = run_job(
            RunOptions(parcels=unpaced_parcels, rtf=0.0, params=list(params), rrd=rrd_file),
            say=say,
        )
    fig.update(
        {
            "unpaced_exit": unpaced.code,
            "unpaced_message": unpaced.message,
            "unpaced_rtf": unpaced_rtf(unpaced.records),
            "unpaced_sim_s": stream_sim_span(unpaced.records),
            "unpaced_sorted": unpaced.summary["sorted_divert"],
            "unpaced_divert": unpaced.summary["divert"],
            "unpaced_controller_p99_ms": unpaced.summary["controller_latency_p99_ms"],
            "unpaced_by_reason": unpaced.summary["by_reason"],
        }
    )
    fig["load_before"] = load0
    fig["load_after"] = os.getloadavg()
    fig["bench_wall_s"] = time.time() - wall0
    return fig


def _ok(value: float, limit: float, above: bool = False) -> str:
    if not math.isfinite(value):
        return "n/a"
    good = value >= limit if above else value <= limit
    return "yes" if good else "**no**"


def render(fig: dict, command: str, machine: dict, revision: str) -> str:
    """The markdown section (between the markers)."""
    f = fig
    extra = "".join(f" --param {p}" for p in f.get("params", ()))
    la = ", ".join(f"{x:.2f}" for x in f["load_before"])
    lb = ", ".join(f"{x:.2f}" for x in f["load_after"])
    rows = [
        (
            "deadline misses",
            f"{f['deadline_misses']:.0f} of {f['cycles']:.0f} cycles "
            f"({100 * f['deadline_miss_share']:.2f} %)",
            "< 0.1 %",
            _ok(f["deadline_miss_share"], TARGETS["deadline_miss_share"]),
        ),
        (
            "cycle lateness p99",
            f"{f['lateness_p99_ms']:.3f} ms",
            "< 0.5 ms",
            _ok(f["lateness_p99_ms"], TARGETS["lateness_p99_ms"]),
        ),
        (
            "cycle lateness p99.9",
            f"{f['lateness_p99_9_ms']:.3f} ms",
            "< 2 ms",
            _ok(f["lateness_p99_9_ms"], TARGETS["lateness_p99_9_ms"]),
        ),
        (
            "lost messages (reliable topics)",
            f"{f['lost_messages']}",
            "0",
            "yes" if f["lost_messages"] == 0 else "**no**",
        ),
        (
            "controller parcel -> command p99",
            f"{f['controller_p99_ms']:.1f} ms "
            f"(p50 {f['controller_p50_ms']:.1f}, max {f['controller_max_ms']:.1f})",
            "<= 50 ms",
            _ok(f["controller_p99_ms"], TARGETS["controller_p99_ms"]),
        ),
        (
            "commands before the parcel reaches R_s",
            f"{f['commands'] - f['commands_late_monitor']} of {f['commands']} "
            f"(simulator: {f['commands_late_simulator']} late; min lead {f['min_lead_s']:.2f} s)",
            "all",
            "yes"
            if f["commands_late_monitor"] == 0 and f["commands_late_simulator"] == 0
            else "**no**",
        ),
        (
            "unpaced RTF (rtf 0, publishing)",
            f"{f['unpaced_rtf']:.1f}x",
            ">= 20x",
            _ok(f["unpaced_rtf"], TARGETS["unpaced_rtf"], above=True),
        ),
    ]
    lines = [
        BEGIN,
        "## Node suite: `python -m benchmarks bench-suite`",
        "",
        f"Command: `{command}` at {revision}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}"
        f", {f['bench_wall_s']:.0f} s. Machine: {machine.get('cpu', '?')}, "
        f"{machine.get('cores', os.cpu_count())} cores, shared: load average {la} before, "
        f"{lb} after (1, 5, 15 min).",
        "",
        f"Paced run: `fence-sorter run --duration {f['duration']:g} --rtf 1{extra}"
        f"{' --rrd FILE' if f.get('rrd') else ''}` (default scene "
        "impact_flexible, "
        f"default stream at 2400 pcs/h): {f['parcels']} parcels, {f['sorted_divert']} of "
        f"{f['divert']} to divert sorted, outcomes {f['by_reason']}; achieved RTF "
        f"{f['paced_rtf']:.3f}; exit {f['paced_exit']} ({f['paced_message']}).",
        "",
        "| figure | measured | target | met |",
        "| --- | --- | --- | --- |",
    ]
    lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    lines += [
        "",
        "Messages on the reliable topics (counters of each node and of the run's monitor):",
        "",
    ]
    lines += ["| topic | counts |", "| --- | --- |"]
    for topic, c in f["counts"].items():
        lines.append(f"| {topic} | " + ", ".join(f"{k} {v}" for k, v in c.items()) + " |")
    lines += [
        "",
        f"Unpaced run: `fence-sorter run --parcels {f['unpaced_parcels']} --rtf 0{extra}"
        f"{' --rrd FILE' if f.get('rrd') else ''}`: "
        f"the stream took {f['unpaced_sim_s']:.1f} s of sim "
        f"time (first scan to last outcome) at {f['unpaced_rtf']:.1f}x real time (sim over "
        "wall time between the simulator's heartbeats around it, /clock, states and markers "
        "published; the loop keeps within 1 s of sim of the scanner's progress, `scan_lead`); "
        f"{f['unpaced_sorted']} of {f['unpaced_divert']} to divert sorted; controller p99 "
        f"{f['unpaced_controller_p99_ms']:.1f} ms; outcomes {f['unpaced_by_reason']} (the "
        "loop keeps within 0.1 s of sim of the published /clock and holds a parcel to divert "
        "for its command; a parcel the scanner publishes too late in sim time at this speed "
        "may still miss its command: the scanner warns of each); exit "
        f"{f['unpaced_exit']} ({f['unpaced_message']}).",
        "",
        _probe_line(f.get("probes", [])),
        "",
        f"Other figures: cycle lateness p50 {f['lateness_p50_ms']:.3f} ms, max "
        f"{f['lateness_max_ms']:.2f} ms; cycle work p99 {f['work_p99_ms']:.3f} ms; publication "
        f"lag (a snapshot's cycle to its last message out, publisher thread) p99 "
        f"{f.get('publish_lag_p99_ms', math.nan):.3f} ms, max "
        f"{f.get('publish_lag_max_ms', math.nan):.2f} ms. The machine has 2 cores shared with "
        "other jobs; the lateness tail follows its load.",
        END,
    ]
    return "\n".join(lines)


def _probe_line(probes: list[dict]) -> str:
    """The host stall probes as one sentence (see :mod:`.stall_probe`)."""
    if not probes:
        return "Host stall probe: not run."
    reps = [StallReport(**p) for p in probes]
    parts = [
        f"{r.gaps_over_1ms} gaps >= 1 ms ({r.gaps_over_2ms} >= 2 ms, longest "
        f"{r.max_gap_ms:.2f} ms) in {r.duration:g} s"
        for r in reps
    ]
    return (
        f"Host stall probe ({reps[0].policy} busy loop, "
        "`python -m benchmarks.stall_probe`, before and after the paced run): "
        + "; ".join(parts)
        + ". A gap is time the loop did not run at all (hypervisor or kernel), which no pacing "
        "can hide: each gap >= 1 ms is a missed 1 kHz deadline whatever the simulator does."
    )


def write_section(path: Path, section: str) -> None:
    """Replace the text between the suite markers (append them if absent); keep the rest."""
    replace_section(path, section, BEGIN, END, append=True)


def write_json(path: Path, fig: dict, command: str, revision: str) -> None:
    """Store ``fig`` with its command, commit and load under "rrd" or "plain" in ``path``,
    keeping the other entry the file holds."""
    try:
        runs = json.loads(path.read_text(encoding="utf-8")).get("runs", {})
    except (OSError, ValueError):
        runs = {}
    runs["rrd" if fig.get("rrd") else "plain"] = {
        "command": command,
        "commit": revision,
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "cores": os.cpu_count(),
        "targets": TARGETS,
        **fig,
    }
    text = json.dumps({"runs": runs}, indent=1, sort_keys=True, default=str)
    path.write_text(text + "\n", encoding="utf-8")
