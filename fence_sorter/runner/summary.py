"""The figures of one run (ROS-free): from the monitor's records to a summary dict and text,
and the run's exit status as far as its own stream decides it (:func:`verdict`)."""

from __future__ import annotations

import math
from collections import Counter

from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.capacity.delivered import delivered_row, describe, limits_verdict, peak
from fence_sorter.jsonsafe import json_safe

#: exit status: a divert parcel of the run's own stream got no outcome
EXIT_INCOMPLETE = 3
#: exit status: every divert parcel has its outcome, but foreign traffic (parcels or commands
#: of another run, messages with the run's id that its key does not vouch for, publishers of
#: the run's topics that are not its nodes: a second /clock) was seen on the run's domain:
#: refused and counted, never in the figures
EXIT_FOREIGN = 4
#: exit status: a parcel of the run was disputed: two authentic messages (or a message and the
#: run's stream) gave its id different specs; the first one was sorted
EXIT_DISPUTED = 6
#: exit status: the recorder could not write the bag (a full disk, any write error): the run
#: went on unrecorded from the time the summary names (docs/guide/recording.md)
EXIT_RECORDING = 5
#: exit status: the run's own stream was handled, but a sorted parcel went over a limit of the
#: paper ((7), (10)-(12), delivered on the plant), an event's simulation failed, or a stroke
#: swept another parcel (a swept-sector intrusion): the run is not clean, the summary names them
EXIT_LIMITS = 7
#: the diagnostics counters of messages a node dropped or refused (where, and why): intake
#: refusals (foreign run or source, rate), middleware losses, duplicates and conflicts of a
#: parcel id, and every validation refusal by its reason (the dotted per-reason keys; their
#: unsuffixed totals are not counted twice)
DROP_COUNTERS = (
    ".foreign",
    ".rate_limited",
    ".lost",
    ".duplicate",
    ".conflict",
    "take_errors",
    "_dropped_",
    "bad_parcels.",
    "rejected_parcels.",
    "commands_rejected.",
)


def _num(text: str | None) -> float:
    try:
        return float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


def _count(text: str | None) -> int:
    n = _num(text)
    return int(n) if math.isfinite(n) else 0


def pick(values: dict[str, str] | None, *needles: str) -> dict[str, str]:
    """Entries of a diagnostics dict whose key contains every needle (case-insensitive)."""
    if not values:
        return {}
    return {k: v for k, v in values.items() if all(n.lower() in k.lower() for n in needles)}


def command_leads(records, belt_speed: float) -> list[float]:
    """Per command: sim time from its publication (its header stamp, the controller's clock;
    else its arrival at the monitor) to the front reaching R_s [s]."""
    leads = []
    for pid, cmd in records.commands.items():
        parcel = records.parcels.get(pid)
        if parcel is None or not cmd["feasible"] or not math.isfinite(cmd["r_s"]):
            continue
        t_rs = parcel["scan_time"] + (cmd["r_s"] - parcel["scan_position_x"]) / belt_speed
        sent = cmd["stamp"] if cmd.get("stamp", 0.0) > 0.0 else cmd["received_sim"]
        leads.append(t_rs - sent)
    return leads


def dropped(diagnostics: dict[str, dict[str, str]]) -> dict[str, dict[str, int]]:
    """Per node: the messages it dropped, by counter (non-zero ones only)."""
    out: dict[str, dict[str, int]] = {}
    for name, values in diagnostics.items():
        node = name.rpartition("/")[2]
        for k, v in values.items():
            if any(c in k for c in DROP_COUNTERS):
                n = int(_num(v)) if math.isfinite(_num(v)) else 0
                if n:
                    out.setdefault(node, {})[k] = n
    return out


def foreign_publishers(diagnostics: dict[str, dict[str, str]]) -> dict[str, list[str]]:
    """Per topic: the publishers the simulator named that are not the run's own nodes."""
    sim = diagnostics.get("fence_sorter/simulator") or {}
    prefix = "foreign_publishers."
    return {k[len(prefix) :]: v.split("; ") for k, v in sim.items() if k.startswith(prefix) and v}


def disputed_ids(records) -> list[int]:
    """Parcel ids with two specs: seen by the monitor, flagged in an outcome, or named by a
    node (``parcels.disputed_ids``)."""
    ids = set(getattr(records, "disputed", ()))
    ids |= {pid for pid, o in records.outcomes.items() if o.get("disputed")}
    for values in records.diagnostics.values():
        for k, v in values.items():
            if k.endswith(".disputed_ids") and v:
                ids |= {int(x) for x in v.split(",") if x.strip().isdigit()}
    return sorted(ids)


def parcel_table(outcomes: dict, expected, divert: set[int], disputed) -> list[dict]:
    """Every parcel of the run's stream with its outcome (``MISSING`` where it has none)."""
    rows = []
    for pid in expected:
        o = outcomes.get(pid)
        rows.append(
            {
                "parcel_id": pid,
                "divert": pid in divert,
                "outcome": o["reason_name"] if o else "MISSING",
                "sorted": bool(o and o["sorted"]),
                "disputed": pid in disputed,
            }
        )
    return rows


def recording_failure(diagnostics: dict[str, dict[str, str]]) -> dict | None:
    """What the recorder said of a failed write (its /diagnostics error): the error, the sim
    time it happened and the sim time of the last message in the bag; None: no failure."""
    rec = diagnostics.get("fence_sorter/recorder") or {}
    if not rec.get("write_error"):
        return None
    return {
        "error": rec["write_error"],
        "failed_at_sim_s": _num(rec.get("write_failed_at_sim_s")),
        "bag_ends_sim_s": _num(rec.get("bag_ends_sim_s")),
        "bag": rec.get("bag"),
        "messages_not_written": _count(rec.get("messages_dropped_write_failed")),
    }


def delivered_rows(records, outcomes: dict, profile: ConstraintProfile, belt_speed: float):
    """Per parcel with an outcome: its stroke, the parcel and what the stroke delivered
    against each limit (:func:`fence_sorter.capacity.delivered.delivered_row`)."""
    return [
        delivered_row(
            pid, o, records.commands.get(pid), records.parcels.get(pid), profile, belt_speed
        )
        for pid, o in sorted(outcomes.items())
    ]


def intrusions(diagnostics: dict[str, dict[str, str]]) -> int:
    """Swept-sector intrusions the simulator saw: a parcel entering the sector of another
    parcel's stroke while it ran."""
    sim = diagnostics.get("fence_sorter/simulator") or {}
    return _count(sim.get("swept_sector_intrusions", sim.get("overlap_warnings")))


def summarise(
    records,
    belt_speed: float,
    expected_ids=None,
    divert_ids=None,
    profile: ConstraintProfile | None = None,
) -> dict:
    """Summary of a run: parcels, outcomes by reason, capacity, peaks, timing, node figures,
    foreign traffic and dropped messages. ``expected_ids``/``divert_ids``: the run's stream;
    with them the figures cover that stream only (an outcome for another id is counted apart),
    and every parcel of it is listed with its outcome. ``profile``: the limits the run is
    judged against (the controller's; paper values by default); failed events are counted
    apart and never enter the peak figures."""
    profile = profile if profile is not None else ConstraintProfile()
    outcomes = records.outcomes
    if expected_ids is not None:
        outcomes = {pid: o for pid, o in outcomes.items() if pid in set(expected_ids)}
    if divert_ids is not None:
        divert = set(divert_ids)
    else:
        divert = {pid for pid, p in records.parcels.items() if p["divert"]}
    by_reason = Counter(o["reason_name"] for o in outcomes.values())
    missed = Counter(
        o["reason_name"] for pid, o in outcomes.items() if not o["sorted"] and pid in divert
    )
    sorted_ids = [pid for pid, o in outcomes.items() if o["sorted"]]
    wrongly = [pid for pid in sorted_ids if pid in records.parcels and pid not in divert]
    scans = sorted(records.parcels[pid]["scan_time"] for pid in outcomes if pid in records.parcels)
    span = scans[-1] - scans[0] if len(scans) > 1 else math.nan
    throughput = 3600.0 * (len(scans) - 1) / span if span and span > 0 else math.nan
    sorted_rate = (
        3600.0 * len(sorted_ids) / span * (len(scans) - 1) / len(scans)
        if span and span > 0
        else math.nan
    )
    leads = command_leads(records, belt_speed)
    ctrl = records.diagnostics.get("fence_sorter/controller")
    sim = records.diagnostics.get("fence_sorter/simulator")
    scanner = records.diagnostics.get("fence_sorter/scanner")
    sensors = records.diagnostics.get("fence_sorter/sensors")
    expected = sorted(expected_ids) if expected_ids is not None else None
    disputed = disputed_ids(records)
    forged_parcels = getattr(records, "forged_parcels", {})
    forged_commands = getattr(records, "forged_commands", {})
    lost = [
        {
            "parcel_id": pid,
            "why": outcomes[pid]["reason_name"] if pid in outcomes else "no outcome",
        }
        for pid in sorted(divert)
        if not (pid in outcomes and outcomes[pid]["sorted"])
    ]
    rows = delivered_rows(records, outcomes, profile, belt_speed)
    judged = _with_failed(outcomes, rows)
    return {
        "limits": limits_verdict(rows, profile),
        "delivered": rows,
        "swept_sector_intrusions": intrusions(records.diagnostics),
        "parcels_expected": len(expected) if expected is not None else None,
        "parcels_seen": len(records.parcels),
        "parcel_messages": records.parcel_messages,
        "outcomes": len(outcomes),
        "outcome_messages": records.outcome_messages,
        "missing_outcomes": (
            [pid for pid in expected if pid not in outcomes] if expected is not None else []
        ),
        "divert_without_outcome": sorted(pid for pid in divert if pid not in outcomes),
        "no_command": sum(
            1 for pid, o in outcomes.items() if pid in divert and o["reason_name"] == "NO_COMMAND"
        ),
        "parameter_changes": parameter_changes(records.diagnostics),
        "parameter_changes_refused": parameter_refusals(records.diagnostics),
        "foreign_outcome_messages": getattr(records, "foreign_outcome_messages", 0),
        "forged_outcome_messages": sum(getattr(records, "forged_outcomes", {}).values()),
        "forged_outcome_ids": sorted(getattr(records, "forged_outcomes", {})),
        "forged_diagnostics": dict(getattr(records, "forged_diagnostics", {})),
        "stale_diagnostics": getattr(records, "stale_diagnostics", 0),
        "foreign_parcel_messages": getattr(records, "foreign_parcel_messages", 0),
        "foreign_command_messages": getattr(records, "foreign_command_messages", 0),
        "forged_parcel_messages": sum(forged_parcels.values()),
        "forged_command_messages": sum(forged_commands.values()),
        "forged_parcel_ids": sorted(
            pid for pid in forged_parcels if expected is None or pid in expected
        ),
        "unexpected_parcel_messages": getattr(records, "unexpected_parcel_messages", 0),
        "outcomes_outside_stream": len(records.outcomes) - len(outcomes),
        "foreign_publishers": foreign_publishers(records.diagnostics),
        "disputed": disputed,
        "divert_not_sorted": lost,
        "parcels": parcel_table(outcomes, expected, divert, set(disputed)) if expected else [],
        "dropped": dropped(records.diagnostics),
        "divert": len(divert),
        "sorted": len(sorted_ids),
        "sorted_divert": len([pid for pid in sorted_ids if pid in divert]),
        "wrongly_sorted": wrongly,
        "by_reason": dict(by_reason),
        "missed_by_reason": dict(missed),
        "missed_examples": {
            name: next(o["reason"] for o in outcomes.values() if o["reason_name"] == name)
            for name in missed
        },
        "throughput_pcs_h": throughput,
        "sorted_pcs_h": sorted_rate,
        "peak_force_N": peak(judged, "peak_normal_force"),
        "peak_force_stiff_N": peak(judged, "peak_normal_force_stiff"),
        "peak_accel_mps2": peak(judged, "peak_normal_accel"),
        "peak_impact_speed_mps": peak(judged, "impact_normal_speed"),
        "peak_exit_speed_mps": peak(judged, "exit_speed_y"),
        "commands": len(records.commands),
        "command_messages": records.command_messages,
        "infeasible_commands": sum(1 for c in records.commands.values() if not c["feasible"]),
        "commands_late": sum(1 for lead in leads if lead < 0.0),
        "command_min_lead_s": min(leads) if leads else math.nan,
        "controller_latency_p99_ms": _num((ctrl or {}).get("latency_p99_ms")),
        "controller_latency_max_ms": _num((ctrl or {}).get("latency_max_ms")),
        "controller": ctrl or {},
        "simulator": sim or {},
        "scanner": scanner or {},
        "sensors": sensors or {},
        "sim_time_s": records.sim_time,
        "recording_failed": recording_failure(records.diagnostics),
    }


def _with_failed(outcomes: dict, rows: list[dict]) -> list[dict]:
    """The outcomes with the ``failed`` flag of their delivered row (peaks skip those)."""
    failed = {r["parcel_id"] for r in rows if r["failed"]}
    return [{**o, "failed": pid in failed} for pid, o in outcomes.items()]


def parameter_changes(diagnostics: dict[str, dict[str, str]]) -> dict[str, list[str]]:
    """Per node: the changes of its parameters it took at run time under the run's key
    (``t=<sim s> NAME=VALUE``, in order)."""
    out = {}
    for name, values in sorted(diagnostics.items()):
        log = values.get("parameter_change_log", "")
        if log:
            out[name.rpartition("/")[2]] = log.split("; ")
    return out


def parameter_refusals(diagnostics: dict[str, dict[str, str]]) -> dict[str, dict]:
    """Per node: the changes of its parameters it refused (without the run's key), with the
    last reasons."""
    out = {}
    for name, values in sorted(diagnostics.items()):
        n = _count(values.get("parameter_changes_refused"))
        if n:
            reasons = [r for r in values.get("parameter_refusals", "").split(" | ") if r]
            out[name.rpartition("/")[2]] = {"count": n, "reasons": reasons}
    return out


def foreign_traffic(s: dict) -> list[str]:
    """What came from outside the run, one phrase each (empty: nothing)."""
    out = []
    if s["foreign_parcel_messages"] or s["foreign_command_messages"]:
        out.append(
            f"{s['foreign_parcel_messages']} parcels and {s['foreign_command_messages']} "
            "commands of another run"
        )
    forged = s.get("forged_parcel_messages", 0) + s.get("forged_command_messages", 0)
    if forged:
        ids = s.get("forged_parcel_ids", [])
        out.append(
            f"{s['forged_parcel_messages']} parcels and {s['forged_command_messages']} commands "
            "with the run's id that its key does not vouch for"
            + (f" (forging parcel ids {ids[:20]} of the run)" if ids else "")
        )
    for node, refused in sorted((s.get("parameter_changes_refused") or {}).items()):
        why = refused["reasons"][-1] if refused["reasons"] else "no key"
        out.append(
            f"{refused['count']} changes of {node}'s parameters without the run's key "
            f"(refused: {why})"
        )
    if s.get("foreign_outcome_messages"):
        out.append(f"{s['foreign_outcome_messages']} outcomes of another run")
    if s.get("forged_outcome_messages"):
        ids = s.get("forged_outcome_ids", [])
        out.append(
            f"{s['forged_outcome_messages']} outcomes with the run's id that its key does not "
            f"vouch for (parcel ids {ids[:20]})"
        )
    forged_diag = s.get("forged_diagnostics") or {}
    if forged_diag:
        out.append(
            "diagnostics in the name of the run's nodes that its key does not vouch for: "
            + ", ".join(f"{name} {n}" for name, n in sorted(forged_diag.items()))
        )
    if s.get("stale_diagnostics"):
        out.append(f"{s['stale_diagnostics']} replayed (older) diagnostics of the run's nodes")
    for topic, names in sorted(s.get("foreign_publishers", {}).items()):
        out.append(f"publishers of {topic} that are not the run's: {'; '.join(names)}")
    return out


def _lost(s: dict) -> str:
    rows = s.get("divert_not_sorted", [])
    if not rows:
        return "every divert parcel of the run was sorted"
    text = ", ".join(f"{r['parcel_id']} ({r['why']})" for r in rows[:20])
    more = f" and {len(rows) - 20} more" if len(rows) > 20 else ""
    return f"divert parcels of the run not sorted: {text}{more}"


def verdict(s: dict) -> tuple[int, str] | None:
    """The exit status the run's own stream calls for, with its reason (naming the run's own
    parcels that were lost, and why); None: clean."""
    foreign = foreign_traffic(s)
    context = f"; foreign traffic: {'; '.join(foreign)}" if foreign else ""
    if s["divert_without_outcome"]:
        ids = s["divert_without_outcome"]
        return EXIT_INCOMPLETE, (
            f"{len(ids)} divert parcels of the run got no outcome: {ids[:20]}; {_lost(s)}"
            + context
        )
    if s.get("disputed"):
        return EXIT_DISPUTED, (
            f"parcels of the run given two specs (disputed): {s['disputed'][:20]}; {_lost(s)}"
            + context
        )
    rec = s.get("recording_failed")
    if rec:
        return EXIT_RECORDING, (
            f"the bag could not be written: {rec['error']} at sim time "
            f"{rec['failed_at_sim_s']:.2f} s; the bag holds every message up to sim time "
            f"{rec['bag_ends_sim_s']:.2f} s, the run went on unrecorded; {_lost(s)}" + context
        )
    if foreign:
        return EXIT_FOREIGN, (
            f"foreign traffic on the run's domain (refused, not in the figures): "
            f"{'; '.join(foreign)}; {_lost(s)}"
        )
    limits = s.get("limits")
    swept = s.get("swept_sector_intrusions", 0)
    if (limits is not None and not limits["clean"]) or swept:
        parts = [] if limits is None or limits["clean"] else [describe(limits)]
        if swept:
            parts.append(f"{swept} swept-sector intrusions (a stroke swept another parcel)")
        return EXIT_LIMITS, "not within the limits: " + "; ".join(parts)
    return None


def simulator_line(sim: dict[str, str]) -> str:
    """The simulator's pacing figures: deadline misses, cycle lateness, real-time factor; a
    figure the node could not take reads n/a. An unpaced run (target real-time factor 0) has
    no deadlines: its lateness is n/a (unpaced)."""
    rtf = pick(sim, "rtf") or pick(sim, "real_time")
    if _num(sim.get("real_time_factor_target")) == 0.0:
        figures = {"cycle_lateness": "n/a (unpaced)", **rtf}
    else:
        figures = {**(pick(sim, "deadline") or pick(sim, "miss")), **pick(sim, "late"), **rtf}
    return ", ".join(f"{k} {_figure(v)}" for k, v in figures.items()) or "n/a"


def _figure(text: str) -> str:
    """A diagnostics value as shown: a number that is not finite (nan, inf) as n/a."""
    return "n/a" if _not_finite(text) else text


#: the summary's entries that hold a node's diagnostics (text values, as published)
NODE_DIAGNOSTICS = ("controller", "simulator", "scanner", "sensors")


def summary_for_json(s: dict) -> dict:
    """The summary as JSON takes it: a figure a node could not take (its diagnostics value
    nan or inf, e.g. an unpaced run's cycle lateness) as null, as the summary's own
    non-finite figures (:func:`fence_sorter.jsonsafe.json_safe`)."""
    out = dict(s)
    for node in NODE_DIAGNOSTICS:
        if isinstance(s.get(node), dict):
            out[node] = {k: None if _not_finite(v) else v for k, v in s[node].items()}
    return json_safe(out)


def _not_finite(text) -> bool:
    """A number written as text that is not finite (nan, inf)."""
    try:
        return not math.isfinite(float(text))
    except (TypeError, ValueError):
        return False


def dense_stream(s: dict) -> str:
    """A phrase when the swept-sector guard declined at least half the divert parcels (the
    parcel behind was in the sector each stroke sweeps): the stream is denser than one fence
    sorts, whatever the planner does; empty otherwise."""
    try:
        occupied = int((s.get("controller") or {}).get("declined.sector_occupied", 0))
    except (TypeError, ValueError):
        return ""
    if not s["divert"] or 2 * occupied < s["divert"]:
        return ""
    return (
        f"{occupied} of {s['divert']} divert parcels declined sector_occupied: the parcel "
        "behind was in the sector the stroke sweeps; space the parcels wider or spread the "
        "destinations over more units"
    )


def format_summary(s: dict) -> str:
    """Human-readable summary."""

    def f(v, spec=".1f", unit=""):
        if v is None or (isinstance(v, float) and not math.isfinite(v)):
            return "n/a"
        return f"{v:{spec}}{' ' + unit if unit else ''}"

    missed = ", ".join(f"{k} {v}" for k, v in sorted(s["missed_by_reason"].items())) or "none"
    reasons = ", ".join(f"{k} {v}" for k, v in sorted(s["by_reason"].items())) or "none"
    n_missed = s["divert"] - s["sorted_divert"]
    lines = [
        f"parcels seen      {s['parcels_seen']}"
        + (f" of {s['parcels_expected']} expected" if s["parcels_expected"] is not None else ""),
        f"outcomes          {s['outcomes']} ({reasons})",
        f"to divert         {s['divert']}: sorted {s['sorted_divert']}, "
        f"missed {n_missed} ({missed})",
    ]
    for name, why in s["missed_examples"].items():
        lines.append(f"  e.g. {name}: {why}")
    if s["wrongly_sorted"]:
        lines.append(f"sorted by mistake {s['wrongly_sorted']}")
    if s["missing_outcomes"]:
        lines.append(f"no outcome        {s['missing_outcomes'][:20]}")
    if s["no_command"]:
        lines.append(
            f"without command   {s['no_command']} divert parcels got NO_COMMAND (no command "
            "before the point of no return: a controller outage costs these)"
        )
    dense = dense_stream(s)
    if dense:
        lines.append(f"stream too dense  {dense}")
    for phrase in foreign_traffic(s):
        lines.append(f"foreign traffic   {phrase} (refused, not counted)")
    if s.get("disputed"):
        lines.append(f"disputed          {s['disputed'][:20]} (two specs for one parcel id)")
    rec = s.get("recording_failed")
    if rec:
        lines.append(
            f"recording FAILED  {rec['error']} at sim time {rec['failed_at_sim_s']:.2f} s; "
            f"the bag complete to {rec['bag_ends_sim_s']:.2f} s ({rec['messages_not_written']} "
            "messages not written)"
        )
    for node, counts in sorted(s["dropped"].items()):
        lines.append(
            f"dropped ({node:<9}) " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
        )
    for node, log in sorted((s.get("parameter_changes") or {}).items()):
        lines.append(f"changed ({node:<8}) " + "; ".join(log) + " (under the run's key)")
    limits = s.get("limits")
    if limits is not None:
        lines.append(f"limits            {describe(limits)}")
    if s.get("swept_sector_intrusions"):
        lines.append(
            f"swept sector      {s['swept_sector_intrusions']} intrusions (a parcel in the "
            "sector of another's stroke)"
        )
    lines += [
        f"capacity          {f(s['throughput_pcs_h'], '.0f', 'pcs/h')} through, "
        f"{f(s['sorted_pcs_h'], '.0f', 'pcs/h')} sorted",
        f"peak force        N {f(s['peak_force_N'], '.1f', 'N')}, N_stiff "
        f"{f(s['peak_force_stiff_N'], '.1f', 'N')}, "
        f"a_N {f(s['peak_accel_mps2'], '.1f', 'm/s^2')}, "
        f"w_n {f(s['peak_impact_speed_mps'], '.2f', 'm/s')}, "
        f"exit {f(s['peak_exit_speed_mps'], '.2f', 'm/s')}",
        f"commands          {s['commands']} ({s['infeasible_commands']} infeasible), late "
        f"{s['commands_late']}, min lead {f(s['command_min_lead_s'], '.3f', 's')}",
        f"controller        latency p99 {f(s['controller_latency_p99_ms'], '.1f', 'ms')}, max "
        f"{f(s['controller_latency_max_ms'], '.1f', 'ms')}",
        f"simulator         {simulator_line(s['simulator'])}",
        f"sim time          {f(s['sim_time_s'], '.2f', 's')}",
    ]
    sensors = s.get("sensors") or {}
    if sensors:  # published samples (what they dropped is under "dropped")
        lines.append(
            f"sensors           {sensors.get('sensors', '?')}: encoder "
            f"{sensors.get('encoder_published', '?')}, camera "
            f"{sensors.get('camera_published', '?')}, gauge "
            f"{sensors.get('strain_published', '?')} samples published"
        )
    return "\n".join(lines)
