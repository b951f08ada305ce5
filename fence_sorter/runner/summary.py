"""The figures of one run (ROS-free): from the monitor's records to a summary dict and text,
and the run's exit status as far as its own stream decides it (:func:`verdict`)."""

from __future__ import annotations

import math
from collections import Counter

#: exit status: a divert parcel of the run's own stream got no outcome
EXIT_INCOMPLETE = 3
#: exit status: every divert parcel has its outcome, but foreign traffic (parcels or commands
#: of another run) was seen on the run's domain: refused and counted, never in the figures
EXIT_FOREIGN = 4
#: the diagnostics counters of messages a node dropped (where, and why)
DROP_COUNTERS = (".foreign", ".rate_limited", ".lost", "take_errors", "_dropped_")


def _num(text: str | None) -> float:
    try:
        return float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


def _max(values) -> float:
    vals = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    return max(vals) if vals else math.nan


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


def summarise(records, belt_speed: float, expected_ids=None, divert_ids=None) -> dict:
    """Summary of a run: parcels, outcomes by reason, capacity, peaks, timing, node figures,
    foreign traffic and dropped messages. ``expected_ids``/``divert_ids``: the run's stream."""
    outcomes = records.outcomes
    divert = {pid for pid, p in records.parcels.items() if p["divert"]}
    if divert_ids is not None:
        divert |= set(divert_ids)
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
    return {
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
        "foreign_parcel_messages": getattr(records, "foreign_parcel_messages", 0),
        "foreign_command_messages": getattr(records, "foreign_command_messages", 0),
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
        "peak_force_N": _max(o["peak_normal_force"] for o in outcomes.values()),
        "peak_force_stiff_N": _max(o["peak_normal_force_stiff"] for o in outcomes.values()),
        "peak_accel_mps2": _max(o["peak_normal_accel"] for o in outcomes.values()),
        "peak_impact_speed_mps": _max(o["impact_normal_speed"] for o in outcomes.values()),
        "peak_exit_speed_mps": _max(o["exit_speed_y"] for o in outcomes.values()),
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
    }


def verdict(s: dict) -> tuple[int, str] | None:
    """The exit status the run's own stream calls for, with its reason; None: clean."""
    if s["divert_without_outcome"]:
        ids = s["divert_without_outcome"]
        return EXIT_INCOMPLETE, f"{len(ids)} divert parcels of the run got no outcome: {ids[:20]}"
    foreign = s["foreign_parcel_messages"] + s["foreign_command_messages"]
    if foreign:
        return EXIT_FOREIGN, (
            f"foreign traffic on the run's domain: {s['foreign_parcel_messages']} parcels, "
            f"{s['foreign_command_messages']} commands of another run (refused, not in the "
            "figures)"
        )
    return None


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
    foreign = s["foreign_parcel_messages"] + s["foreign_command_messages"]
    if foreign:
        lines.append(
            f"foreign traffic   {s['foreign_parcel_messages']} parcels, "
            f"{s['foreign_command_messages']} commands of another run (refused, not counted)"
        )
    for node, counts in sorted(s["dropped"].items()):
        lines.append(
            f"dropped ({node:<9}) " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
        )
    sim = s["simulator"]
    deadline = pick(sim, "deadline") or pick(sim, "miss")
    lateness = pick(sim, "late")
    rtf = pick(sim, "rtf") or pick(sim, "real_time")
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
        "simulator         "
        + (", ".join(f"{k} {v}" for k, v in {**deadline, **lateness, **rtf}.items()) or "n/a"),
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
