"""What each stroke delivered on the plant against the paper's limits, parcel by parcel.

The planner predicts a stroke's figures; the plant (the simulator's fence and the parcel
itself) delivers them. :func:`delivered_row` puts, for one parcel, the stroke it got (R_s,
t1, alpha_k), the parcel (mass, A, B), the planned and the delivered figures of each limit
and their margins side by side; :func:`limits_verdict` sums the rows of a run: the parcels
over each limit, the worst excess, the failed events (counted apart from every peak figure).

The limits judged on the plant are those with a delivered figure:

- (7)  (A - R_s)/v - t1 <= 0, analytic from the stroke and the parcel (A: the yawed extent
  along the belt);
- (10) w_n <= w_dop, (11) a_N <= a_Ndop, (12) ydot <= ydot_dop, from the outcome.

(8) is the outcome itself (a sorted parcel crossed y0 = s); (9) has no delivered figure (the
planner checks it on its own model). Shared by the run's summary and by ``analyze``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from fence_sorter.capacity.constraints import ConstraintProfile, margin_working_time
from fence_sorter.codes import OutcomeCode

#: the limits with a delivered figure on the plant, in the paper's numbering
PLANT_LIMITS = (7, 10, 11, 12)
#: per limit: the outcome's delivered figure, the command's planned one, the name in tables
FIGURES = {
    10: ("impact_normal_speed", "predicted_impact_speed", "impact_speed_mps"),
    11: ("peak_normal_accel", "predicted_peak_accel", "accel_mps2"),
    12: ("exit_speed_y", "predicted_exit_speed", "exit_speed_mps"),
}
#: the outcome codes of an event whose simulation failed: its figures are not physics
FAILED_CODES = (OutcomeCode.SOLVER_FAILURE,)
#: row columns (CSV order) of :func:`delivered_row`
ROW_COLUMNS = [
    "parcel_id", "outcome", "sorted", "failed", "mass_kg", "length_a_m", "width_b_m", "yaw_rad",
    "r_s_m", "t1_s", "alpha_k_rad",
    "planned_impact_speed_mps", "delivered_impact_speed_mps", "limit_impact_speed_mps",
    "planned_accel_mps2", "delivered_accel_mps2", "limit_accel_mps2",
    "planned_exit_speed_mps", "delivered_exit_speed_mps", "limit_exit_speed_mps",
    "margin_7_s", "margin_10_mps", "margin_11_mps2", "margin_12_mps", "over_limits",
]  # fmt: skip


def _f(v) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return math.nan
    return x


def limit_value(profile: ConstraintProfile, c: int) -> float:
    """The admissible value of limit ``c`` (10)-(12) in ``profile``."""
    return {10: profile.w_dop, 11: profile.a_ndop, 12: profile.ydot_dop}[c]


def over_plant_limits(figures: Mapping, profile: ConstraintProfile) -> list[int]:
    """The active limits of (10)-(12) that an outcome's delivered ``figures`` (the SortOutcome
    field names: ``impact_normal_speed``, ``peak_normal_accel``, ``exit_speed_y``) go over."""
    out = []
    for c, (got, _, _) in FIGURES.items():
        value = _f(figures.get(got))
        if c in profile.active and math.isfinite(value) and value > limit_value(profile, c):
            out.append(c)
    return out


def delivered_row(
    parcel_id: int,
    outcome: Mapping,
    command: Mapping | None,
    parcel: Mapping | None,
    profile: ConstraintProfile,
    belt_speed: float,
) -> dict:
    """One parcel: its stroke, the parcel, planned and delivered figures, margins (<= 0 met)
    and the active limits a SORTED parcel went over (``over_limits``; empty when within).

    ``outcome``: the fields of SortOutcome (``reason_name``, ``sorted``, the figures);
    ``command``: of FenceCommand (``r_s``, ``t1``, ``alpha_k``, ``predicted_*``) or None;
    ``parcel``: of Parcel (``mass``, ``length_a``, ``width_b``, ``yaw``) or None.
    """
    cmd = command or {}
    p = parcel or {}
    reason = str(outcome.get("reason_name", ""))
    failed = reason in {c.name for c in FAILED_CODES}
    row = {
        "parcel_id": int(parcel_id),
        "outcome": reason,
        "sorted": bool(outcome.get("sorted", False)),
        "failed": failed,
        "mass_kg": _f(p.get("mass")),
        "length_a_m": _f(p.get("length_a")),
        "width_b_m": _f(p.get("width_b")),
        "yaw_rad": _f(p.get("yaw", 0.0)),
        "r_s_m": _f(cmd.get("r_s")),
        "t1_s": _f(cmd.get("t1")),
        "alpha_k_rad": _f(cmd.get("alpha_k")),
    }
    margins: dict[int, float] = {}
    for c, (got, planned, name) in FIGURES.items():
        limit = limit_value(profile, c)
        value = _f(outcome.get(got))
        row[f"planned_{name}"] = _f(cmd.get(planned))
        row[f"delivered_{name}"] = value
        row[f"limit_{name}"] = limit
        margins[c] = value - limit if not failed else math.nan
    yaw = row["yaw_rad"] if math.isfinite(row["yaw_rad"]) else 0.0
    extent = row["length_a_m"] * abs(math.cos(yaw)) + row["width_b_m"] * abs(math.sin(yaw))
    margins[7] = (
        margin_working_time(extent, row["r_s_m"], belt_speed, row["t1_s"])
        if belt_speed > 0
        else math.nan
    )
    row["margin_7_s"] = margins[7]
    row["margin_10_mps"] = margins[10]
    row["margin_11_mps2"] = margins[11]
    row["margin_12_mps"] = margins[12]
    over = [
        c
        for c in PLANT_LIMITS
        if c in profile.active and row["sorted"] and math.isfinite(margins[c]) and margins[c] > 0
    ]
    row["over_limits"] = over
    return row


def limits_verdict(rows: Iterable[Mapping], profile: ConstraintProfile) -> dict:
    """The run's account of its limits: per active plant limit the sorted parcels over it and
    the worst excess (value, limit, parcel); the failed events; ``clean``: none of either.

    A failed event's figures are not physics: it is named in ``failed_events`` and left out of
    every peak and excess."""
    rows = list(rows)
    over: dict[str, list[int]] = {}
    worst: dict[str, dict] = {}
    for c in PLANT_LIMITS:
        if c not in profile.active:
            continue
        ids = [r["parcel_id"] for r in rows if c in r["over_limits"]]
        over[str(c)] = ids
        if not ids:
            continue
        key = f"margin_{c}_" + ("s" if c == 7 else FIGURES[c][2].rpartition("_")[2])
        top = max((r for r in rows if c in r["over_limits"]), key=lambda r: r[key])
        entry = {"parcel_id": top["parcel_id"], "excess": top[key]}
        if c in FIGURES:
            name = FIGURES[c][2]
            entry.update(
                delivered=top[f"delivered_{name}"],
                planned=top[f"planned_{name}"],
                limit=top[f"limit_{name}"],
            )
        worst[str(c)] = entry
    failed = sorted(r["parcel_id"] for r in rows if r["failed"])
    return {
        "active": [c for c in PLANT_LIMITS if c in profile.active],
        "limits": {"10": profile.w_dop, "11": profile.a_ndop, "12": profile.ydot_dop},
        "over_limit": over,
        "worst_excess": worst,
        "parcels_over_limits": sorted({pid for ids in over.values() for pid in ids}),
        "failed_events": failed,
        "clean": not failed and not any(over.values()),
    }


def describe(verdict: Mapping) -> str:
    """One line: whether every sorted parcel stayed within its limits, naming the parcels."""
    parts = []
    for c, ids in verdict["over_limit"].items():
        if not ids:
            continue
        w = verdict["worst_excess"][c]
        detail = (
            f"worst {w['parcel_id']}: {w['delivered']:.3g} against {w['limit']:.3g} "
            f"(planned {w['planned']:.3g})"
            if "delivered" in w
            else f"worst {w['parcel_id']}: {w['excess']:.3g} s"
        )
        parts.append(f"({c}) {len(ids)} sorted parcels over it {ids[:20]}, {detail}")
    if verdict["failed_events"]:
        ids = verdict["failed_events"]
        parts.append(f"{len(ids)} failed events {ids[:20]} (not in the peaks)")
    if not parts:
        active = ", ".join(f"({c})" for c in verdict["active"])
        return f"every sorted parcel within {active}; no failed event"
    return "; ".join(parts)


def peak(rows: Iterable[Mapping], key: str) -> float:
    """The largest finite ``key`` over the rows of events that did not fail."""
    vals = [_f(r.get(key)) for r in rows if not r.get("failed")]
    vals = [v for v in vals if math.isfinite(v)]
    return max(vals) if vals else math.nan


__all__ = [
    "FAILED_CODES",
    "PLANT_LIMITS",
    "ROW_COLUMNS",
    "delivered_row",
    "describe",
    "limit_value",
    "limits_verdict",
    "over_plant_limits",
    "peak",
]
