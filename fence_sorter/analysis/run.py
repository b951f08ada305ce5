"""A recorded run as arrays, the per-parcel table, and its check against the live outcomes.

:func:`load_run` turns a :class:`~fence_sorter.recording.bagread.BagContents` into a
:class:`RecordedRun`: the scene as the bag shows it (belt width, belt and chute from /markers),
the scanned parcels, commands and live outcomes (/sort_outcomes), and time series per parcel
(/load_states) and of the fence (/fence_state), all on sim time (header stamps) [s].

:func:`parcel_table` gives one row per parcel: the figures the simulator computed at its full
step rate and published live (impact speed, peak N and N_stiff, peak acceleration, exit speed,
time in the working space), and the same quantities re-derived from the recorded states, which
are sampled at the publish rate. :func:`check_against_live` says where the two disagree beyond
what the sampling explains (a sample can only underestimate a peak; exit speed and the time in
the working space are interpolated to the crossing of y0 = s). SI units throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fence_sorter.analysis.events import (
    SortEventData,
    check_event,
    event_figures,
    risk_of,
    risk_summary,
)
from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.capacity.delivered import ROW_COLUMNS, delivered_row, limits_verdict
from fence_sorter.codes import OutcomeCode, Stage, code_name
from fence_sorter.recording import topics
from fence_sorter.recording.bagread import BagContents
from fence_sorter.stamps import time_to_sec

NAN = math.nan
#: LoadState stages while the fence works on the parcel (E1 .. E4)
WORKED_STAGES = (1, 2, 3, 4)
DEFAULT_BELT_WIDTH = 0.7  # [m] impact_flexible, used only when the bag has no /markers

# Tolerances of the check against the live outcomes (sampling at the publish rate explains
# differences up to these).
PEAK_RTOL = 0.02  # sampled peaks may not exceed the live peak by more than this
EXIT_SPEED_RTOL, EXIT_SPEED_ATOL = 0.05, 0.03  # [-], [m/s]
TIME_WS_ATOL_PERIODS = 1.5  # time in the working space, in publish periods


@dataclass
class Series:
    """Time series of one parcel (LoadState) as arrays, sorted by time."""

    t: np.ndarray
    stage: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    n: np.ndarray  # N [N]
    n_stiff: np.ndarray  # N_stiff [N]
    cx: np.ndarray  # contact point [m]
    cy: np.ndarray


@dataclass
class FenceSeries:
    t: np.ndarray
    alpha: np.ndarray  # alpha_w [rad]
    rate: np.ndarray
    tip: np.ndarray  # tip deflection [m]
    node_x: list[np.ndarray]
    node_y: list[np.ndarray]


@dataclass
class RecordedRun:
    belt_width: float
    belt_x: tuple[float, float]
    chute: tuple[float, float, float, float] | None  # centre x, y, size x, y [m]
    parcels: dict[int, dict]
    commands: dict[int, dict]
    outcomes: dict[int, dict]
    series: dict[int, Series]
    fence: FenceSeries
    publish_period: float  # median spacing of the state samples [s]
    belt_speed: float
    diagnostics: dict[str, dict[str, str]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    events: dict[int, SortEventData] = field(default_factory=dict)  # /sort_events by parcel


def _fields(msg, names) -> dict:
    return {n: getattr(msg, n, NAN) for n in names}  # NaN: a bag from before the field


PARCEL_FIELDS = (
    "parcel_id length_a width_b height mass cog_offset_x cog_offset_y lateral_gap yaw mu_belt "
    "mu_fence divert scan_position_x"
).split()
OUTCOME_FIELDS = (
    "parcel_id sorted reason reason_code peak_normal_force peak_normal_force_stiff "
    "peak_normal_accel impact_normal_speed exit_speed_y y_max time_in_working_space w_dop a_ndop "
    "impact_speed_margin accel_margin drop_height"
).split()
COMMAND_FIELDS = (
    "parcel_id start_mode r_s t1 alpha_k predicted_capacity_pcs_h predicted_impact_speed "
    "predicted_peak_accel predicted_exit_speed predicted_peak_force feasible reason"
).split()


def load_run(bag: BagContents) -> RecordedRun:
    """Arrays of a recorded run (what is missing from the bag is noted, never fatal)."""
    notes: list[str] = []
    parcels, commands, outcomes = {}, {}, {}
    for m in bag.by_topic(topics.PARCELS):
        d = _fields(m.msg, PARCEL_FIELDS)
        d["scan_time"] = time_to_sec(m.msg.scan_time)
        d["divert"] = bool(d["divert"])
        parcels[int(d["parcel_id"])] = d
    for m in bag.by_topic(topics.FENCE_COMMANDS):
        d = _fields(m.msg, COMMAND_FIELDS)
        d["stamp"] = time_to_sec(m.msg.header.stamp)
        commands[int(d["parcel_id"])] = d
    for m in bag.by_topic(topics.SORT_OUTCOMES):
        d = _fields(m.msg, OUTCOME_FIELDS)
        d["t"] = time_to_sec(m.msg.header.stamp)
        d["sorted"] = bool(d["sorted"])
        d["reason_name"] = code_name(OutcomeCode, d["reason_code"])
        outcomes[int(d["parcel_id"])] = d

    events = {}
    for m in bag.by_topic(topics.SORT_EVENTS):
        ev = SortEventData.from_msg(m.msg)
        events[ev.parcel_id] = ev

    rows: dict[int, list] = {}
    for m in bag.by_topic(topics.LOAD_STATES):
        s = m.msg
        p, v = s.pose.position, s.twist.linear
        yaw = 2.0 * math.atan2(s.pose.orientation.z, s.pose.orientation.w)
        rows.setdefault(int(s.parcel_id), []).append(
            (
                time_to_sec(s.header.stamp), s.stage, p.x, p.y, yaw, v.x, v.y,
                s.contact_normal_force, s.contact_normal_force_stiff,
                s.contact_point.x, s.contact_point.y,
            )
        )  # fmt: skip
    series = {}
    for pid, r in rows.items():
        a = np.array(sorted(r), dtype=float)
        series[pid] = Series(*(a[:, k] for k in range(11)))

    fence_msgs = bag.by_topic(topics.FENCE_STATE)
    fence_msgs.sort(key=lambda m: time_to_sec(m.msg.header.stamp))
    fence = FenceSeries(
        np.array([time_to_sec(m.msg.header.stamp) for m in fence_msgs]),
        np.array([m.msg.drive_angle for m in fence_msgs]),
        np.array([m.msg.drive_rate for m in fence_msgs]),
        np.array([m.msg.tip_deflection for m in fence_msgs]),
        [np.asarray(m.msg.node_x, dtype=float) for m in fence_msgs],
        [np.asarray(m.msg.node_y, dtype=float) for m in fence_msgs],
    )
    if not fence_msgs:
        notes.append("no /fence_state in the bag: no fence plots")

    belt_width, belt_x, chute = DEFAULT_BELT_WIDTH, (-3.0, 3.0), None
    found_belt = False
    for m in bag.by_topic(topics.MARKERS):
        for mk in m.msg.markers:
            if mk.ns == "belt" and mk.action == 0 and not found_belt:
                belt_width = float(mk.scale.y)
                x0 = mk.pose.position.x
                belt_x = (x0 - 0.5 * mk.scale.x, x0 + 0.5 * mk.scale.x)
                found_belt = True
            elif mk.ns == "chute" and chute is None:
                chute = (mk.pose.position.x, mk.pose.position.y, mk.scale.x, mk.scale.y)
        if found_belt and chute is not None:
            break
    if not found_belt:
        notes.append(f"no belt marker in /markers: belt width s = {DEFAULT_BELT_WIDTH} m assumed")

    dts = np.diff(fence.t) if len(fence.t) > 2 else np.array([])
    period = float(np.median(dts)) if dts.size else NAN
    on_belt = [
        s.vx[(s.stage == 0) & (s.n == 0.0)] for s in series.values() if np.any(s.stage == 0)
    ]
    vx = np.concatenate(on_belt) if on_belt else np.array([])
    belt_speed = float(np.median(vx)) if vx.size else NAN

    diagnostics: dict[str, dict[str, str]] = {}
    for m in bag.by_topic(topics.DIAGNOSTICS):
        for st in m.msg.status:
            diagnostics[st.name] = {kv.key: kv.value for kv in st.values}
    return RecordedRun(
        belt_width, belt_x, chute, parcels, commands, outcomes, series, fence, period,
        belt_speed, diagnostics, notes, events,
    )  # fmt: skip


# -- per-parcel figures from the sampled states -------------------------------------------------
def crossing(
    s: Series, belt_width: float, period: float, t_next: float | None = None
) -> tuple[float, float] | None:
    """(time, vy) where C_s crosses y0 = s, or None if the samples do not show it crossing.

    A sample past the edge: interpolated between it and the one before. Else the parcel left
    the line at the crossing, after its last sample and by the next snapshot, which no longer
    holds it: ``t_next``, the first fence sample after the last one (None: one publish period
    later; inf: no bound). The crossing is extrapolated from the last sample at the
    acceleration a_y of the last two, constant (the fence's push, or the belt's friction once
    released): y + vy tau + a_y tau^2 / 2 = s, first root; a parcel that stops short of the
    edge (vy^2 < 2 |a_y| (s - y) when decelerating) or crosses more than half a period after
    the next snapshot did not cross there."""
    if s.t.size == 0:
        return None
    inside = np.nonzero(s.y >= belt_width)[0]
    if inside.size:  # a sample past the edge: interpolate between it and the one before
        k = int(inside[0])
        if k == 0:
            return float(s.t[0]), float(s.vy[0])
        f = (belt_width - s.y[k - 1]) / (s.y[k] - s.y[k - 1])
        return (
            float(s.t[k - 1] + f * (s.t[k] - s.t[k - 1])),
            float(s.vy[k - 1] + f * (s.vy[k] - s.vy[k - 1])),
        )
    if not math.isfinite(period):
        return None
    d, vy = belt_width - float(s.y[-1]), float(s.vy[-1])
    ay = float((s.vy[-1] - s.vy[-2]) / (s.t[-1] - s.t[-2])) if s.t.size > 1 else 0.0
    tau = _time_to_reach(d, vy, ay)
    window = period if t_next is None else t_next - float(s.t[-1])
    if tau is None or tau > window + 0.5 * period:
        return None
    return float(s.t[-1] + tau), vy + ay * tau


def _time_to_reach(d: float, v: float, a: float) -> float | None:
    """First tau >= 0 with v tau + a tau^2 / 2 = d (d > 0) at constant acceleration a; None if
    the motion never covers d (it stops short, or moves away)."""
    if a == 0.0:
        return d / v if v > 0.0 else None
    disc = v * v + 2.0 * a * d
    if disc < 0.0:
        return None  # decelerates to rest short of d
    root = math.sqrt(disc)
    # the smaller non-negative root, written without cancellation
    tau = 2.0 * d / (v + root) if v + root > 0.0 else (root - v) / a
    return tau if tau >= 0.0 else None


def sampled_exit_speed(s: Series, cross: tuple[float, float], belt_width: float) -> float:
    """The exit speed the states show at ``cross`` (:func:`crossing`): NaN when the crossing
    is extrapolated from a last sample the fence still pushes (N > 0), whose push up to the
    release is not in the states (the constant-acceleration extrapolation then misses it by
    up to a_N times the time to the edge)."""
    if not np.any(s.y >= belt_width) and s.n[-1] > 0.0:
        return NAN
    return cross[1]


def sampled_figures(run: RecordedRun, pid: int) -> dict:
    """Figures of one parcel re-derived from its recorded states (NaN where not derivable)."""
    s = run.series.get(pid)
    out = dict(
        samples=0, sorted=False, peak_normal_force=NAN, peak_normal_force_stiff=NAN,
        peak_accel=NAN, exit_speed_y=NAN, time_in_working_space=NAN, y_max=NAN,
    )  # fmt: skip
    if s is None or s.t.size == 0:
        return out
    out["samples"] = int(s.t.size)
    out["y_max"] = float(np.max(s.y))
    touched = np.isin(s.stage, WORKED_STAGES)
    if np.any(touched):
        out["peak_normal_force"] = float(np.max(s.n))
        out["peak_normal_force_stiff"] = float(np.max(s.n_stiff))
        if s.t.size > 1:
            dt = np.diff(s.t)
            ok = dt > 0
            a = np.hypot(np.diff(s.vx)[ok], np.diff(s.vy)[ok]) / dt[ok]
            out["peak_accel"] = float(np.max(a)) if a.size else NAN
    # the snapshot that no longer holds it (none recorded: taken one publish period on)
    later = run.fence.t[run.fence.t > s.t[-1] + 1e-9]
    cross = crossing(s, run.belt_width, run.publish_period, later[0] if later.size else None)
    sorted_ = bool(np.any(s.stage == Stage.SORTED)) or cross is not None
    out["sorted"] = sorted_
    if cross is not None:
        out["exit_speed_y"] = sampled_exit_speed(s, cross, run.belt_width)
        spec = run.parcels.get(pid)
        if spec is not None and math.isfinite(run.belt_speed) and run.belt_speed > 0:
            t_enter = spec["scan_time"] + (0.0 - spec["scan_position_x"]) / run.belt_speed
            out["time_in_working_space"] = cross[0] - t_enter
    return out


TABLE_COLUMNS = [
    "parcel_id", "divert", "sorted", "reason", "reason_text", "source", "impact_speed_mps",
    "peak_N", "peak_N_stiff", "peak_accel_mps2", "exit_speed_mps", "time_in_ws_s", "y_max_m",
    "sampled_sorted", "sampled_peak_N", "sampled_peak_N_stiff", "sampled_peak_accel_mps2",
    "sampled_exit_speed_mps", "sampled_time_in_ws_s", "samples", "event_steps",
    "event_impact_speed_mps", "event_peak_N", "event_peak_N_stiff", "event_peak_accel_mps2",
    "w_dop_mps", "a_ndop_mps2", "impact_speed_margin", "accel_margin", "drop_height_m",
    "agrees", "disagreements",
    *[c for c in ROW_COLUMNS if c not in ("parcel_id", "sorted")],
]  # fmt: skip


def run_limits(run: RecordedRun) -> ConstraintProfile:
    """The limits the run's controller planned for (its /diagnostics ``limits.*``); a bag
    without them: the outcomes' w_dop and a_Ndop, the paper's ydot_dop, every constraint."""
    diag = run.diagnostics.get("fence_sorter/controller") or {}
    if "limits.w_dop" in diag:
        active = tuple(int(c) for c in diag.get("limits.active", "").split(",") if c.strip())
        return ConstraintProfile(
            float(diag["limits.w_dop"]),
            float(diag["limits.a_ndop"]),
            float(diag["limits.ydot_dop"]),
            active or ConstraintProfile().active,
        )
    any_outcome = next(iter(run.outcomes.values()), {})
    w_dop, a_ndop = any_outcome.get("w_dop", NAN), any_outcome.get("a_ndop", NAN)
    default = ConstraintProfile()
    return ConstraintProfile(
        w_dop if _num(w_dop) and w_dop > 0 else default.w_dop,
        a_ndop if _num(a_ndop) and a_ndop > 0 else default.a_ndop,
    )


def parcel_table(run: RecordedRun) -> list[dict]:
    """One row per parcel seen in the bag (scanned, with states or with an outcome)."""
    ids = sorted(set(run.parcels) | set(run.outcomes) | set(run.series))
    profile = run_limits(run)
    rows = []
    for pid in ids:
        o = run.outcomes.get(pid)
        spec = run.parcels.get(pid)
        smp = sampled_figures(run, pid)
        row = {
            "parcel_id": pid,
            "divert": spec["divert"] if spec else None,
            "sorted": o["sorted"] if o else smp["sorted"],
            "reason": o["reason_name"] if o else "NO_OUTCOME_IN_BAG",
            "reason_text": o["reason"] if o else "no /sort_outcomes message in the bag",
            "source": "live outcome" if o else "recorded states",
            "impact_speed_mps": o["impact_normal_speed"] if o else NAN,
            "peak_N": o["peak_normal_force"] if o else smp["peak_normal_force"],
            "peak_N_stiff": o["peak_normal_force_stiff"] if o else smp["peak_normal_force_stiff"],
            "peak_accel_mps2": o["peak_normal_accel"] if o else smp["peak_accel"],
            "exit_speed_mps": o["exit_speed_y"] if o else smp["exit_speed_y"],
            "time_in_ws_s": o["time_in_working_space"] if o else smp["time_in_working_space"],
            "y_max_m": o["y_max"] if o else smp["y_max"],
            "sampled_sorted": smp["sorted"],
            "sampled_peak_N": smp["peak_normal_force"],
            "sampled_peak_N_stiff": smp["peak_normal_force_stiff"],
            "sampled_peak_accel_mps2": smp["peak_accel"],
            "sampled_exit_speed_mps": smp["exit_speed_y"],
            "sampled_time_in_ws_s": smp["time_in_working_space"],
            "samples": smp["samples"],
        }
        ev = run.events.get(pid)
        fig = event_figures(ev) if ev is not None else None
        row.update(
            event_steps=fig["steps"] if fig else 0,
            event_impact_speed_mps=fig["impact_normal_speed"] if fig else NAN,
            event_peak_N=fig["peak_normal_force"] if fig else NAN,
            event_peak_N_stiff=fig["peak_normal_force_stiff"] if fig else NAN,
            event_peak_accel_mps2=fig["peak_normal_accel"] if fig else NAN,
        )
        risk = risk_of(o) if o else None
        row.update(
            w_dop_mps=risk["w_dop"] if risk else NAN,
            a_ndop_mps2=risk["a_ndop"] if risk else NAN,
            impact_speed_margin=risk["impact_speed_margin"] if risk else NAN,
            accel_margin=risk["accel_margin"] if risk else NAN,
            drop_height_m=risk["drop_height"] if risk else NAN,
        )
        problems = check_row(row, o, run.publish_period)
        if fig is not None and o is not None:
            problems += check_event(fig, o)
        elif run.events and o is not None and _num(o["impact_normal_speed"]):
            problems.append("no /sort_events message for the parcel's stroke")
        if o is not None and risk is not None:
            problems += check_risk(o, risk)
        row["agrees"] = not problems if o is not None else None
        row["disagreements"] = "; ".join(problems)
        if o is not None:
            d = delivered_row(pid, o, run.commands.get(pid), spec, profile, run.belt_speed)
            row.update({k: v for k, v in d.items() if k not in ("parcel_id", "sorted")})
        rows.append(row)
    return rows


def _num(v) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def check_row(row: dict, outcome: dict | None, period: float) -> list[str]:
    """Where the sampled figures of a parcel contradict its live outcome."""
    if outcome is None:
        return []
    out = []
    if row["samples"] and row["sampled_sorted"] != outcome["sorted"]:
        out.append(f"sorted: states say {row['sampled_sorted']}, live outcome {outcome['sorted']}")
    for key, live_key in (
        ("sampled_peak_N", "peak_normal_force"),
        ("sampled_peak_N_stiff", "peak_normal_force_stiff"),
        ("sampled_peak_accel_mps2", "peak_normal_accel"),
    ):
        smp, live = row[key], outcome[live_key]
        if _num(smp) and _num(live) and smp > live * (1.0 + PEAK_RTOL) + 1e-9:
            out.append(f"{key} {smp:.4g} exceeds the live peak {live:.4g}")
        if _num(smp) and smp > 0 and not _num(live):
            out.append(f"{key} {smp:.4g} but the live outcome has no contact")
    smp, live = row["sampled_exit_speed_mps"], outcome["exit_speed_y"]
    if outcome["sorted"] and _num(smp) and _num(live):
        if abs(smp - live) > EXIT_SPEED_RTOL * abs(live) + EXIT_SPEED_ATOL:
            out.append(f"exit speed: sampled {smp:.4g} m/s, live {live:.4g} m/s")
    smp, live = row["sampled_time_in_ws_s"], outcome["time_in_working_space"]
    if outcome["sorted"] and _num(smp) and _num(live) and _num(period):
        if abs(smp - live) > TIME_WS_ATOL_PERIODS * period:
            out.append(f"time in working space: sampled {smp:.4g} s, live {live:.4g} s")
    return out


def check_risk(outcome: dict, risk: dict) -> list[str]:
    """Where the outcome's published margins and drop height differ from the closed forms."""
    out = []
    for key in ("impact_speed_margin", "accel_margin", "drop_height"):
        live, ref = outcome.get(key, NAN), risk[key]
        if _num(live) and _num(ref) and abs(live - ref) > 1e-9 * max(1.0, abs(ref)):
            out.append(f"{key}: published {live:.6g}, closed form {ref:.6g}")
    return out


def incomplete_records(run: RecordedRun) -> dict[str, list[int]]:
    """Parcel ids whose outcome or command is in the bag without their /parcels message: the
    bag lost the scan (the stream's counts and capacity are then wrong)."""
    return {
        "outcomes_without_parcel": sorted(set(run.outcomes) - set(run.parcels)),
        "commands_without_parcel": sorted(set(run.commands) - set(run.parcels)),
    }


def stream_summary(run: RecordedRun, rows: list[dict]) -> dict:
    """Capacity and share sorted of the stream (definitions as fence_sorter.runner.summary)."""
    scans = sorted(p["scan_time"] for pid, p in run.parcels.items() if pid in run.outcomes)
    span = scans[-1] - scans[0] if len(scans) > 1 else NAN
    throughput = 3600.0 * (len(scans) - 1) / span if _num(span) and span > 0 else NAN
    divert = [r for r in rows if r["divert"]]
    sorted_divert = [r for r in divert if r["sorted"]]
    sorted_all = [r for r in rows if r["sorted"]]
    sorted_rate = (
        3600.0 * len(sorted_all) / span * (len(scans) - 1) / len(scans)
        if _num(span) and span > 0
        else NAN
    )
    planned = [
        c["predicted_capacity_pcs_h"]
        for c in run.commands.values()
        if c["feasible"] and _num(c["predicted_capacity_pcs_h"])
    ]
    checked = [r for r in rows if r["agrees"] is not None]
    return {
        "parcels": len(rows),
        "parcels_scanned": len(run.parcels),
        "outcomes_live": len(run.outcomes),
        "divert": len(divert),
        "sorted_divert": len(sorted_divert),
        "share_sorted": len(sorted_divert) / len(divert) if divert else NAN,
        "wrongly_sorted": [r["parcel_id"] for r in sorted_all if r["divert"] is False],
        "throughput_pcs_h": throughput,
        "sorted_pcs_h": sorted_rate,
        "planned_capacity_pcs_h_min": min(planned) if planned else NAN,
        "planned_capacity_pcs_h_mean": float(np.mean(planned)) if planned else NAN,
        "belt_speed_mps": run.belt_speed,
        "belt_width_m": run.belt_width,
        "publish_period_s": run.publish_period,
        "agrees_with_live": all(r["agrees"] for r in checked) if checked else None,
        "parcels_checked": len(checked),
        "parcels_disagreeing": [r["parcel_id"] for r in checked if not r["agrees"]],
        "parcels_without_outcome": [r["parcel_id"] for r in rows if r["agrees"] is None],
        "sort_events": len(run.events),
        "damage_risk": risk_summary(rows),
        "limits": limits_verdict([r for r in rows if "over_limits" in r], run_limits(run)),
        **incomplete_records(run),
    }
