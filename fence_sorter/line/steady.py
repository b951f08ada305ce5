"""A line run's steady state: its window, the cohort of parcels first inducted in it, what the
stream offered, and whether (and where) a queue grows.

The window runs from one loop cycle after the first parcel's first induction (the fill: until
then no parcel has come back from the loop) to the last parcel's first induction (after it
the line drains). The cohort is the parcels whose front first crossed the induction scan
line X = 0 in it; its fate is read at the end of the run (sorted, rejected, failed, lost with
a unit, still on the line), so the cohort's sorted / inducted is at most 1 by construction.

A queue grows where waiting times grow with the time they are measured at: the induction's
(a new parcel's first induction less its arrival in the stream: the holds for the gapping
induction's ``min_gap`` and for returning parcels) and the merge's (a returning parcel's
wait for a gap at the induction). The line is saturated when either grows faster than
:data:`SATURATION_GROWTH` seconds per second (for the induction: inducted / offered below
about 1 / (1 + SATURATION_GROWTH)).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = [
    "QUEUES", "SATURATION_GROWTH", "growth", "per_hour", "steady_state", "steady_window"
]  # fmt: skip

#: waiting time a queue adds per second of sim time above which it is saturated [s/s]
SATURATION_GROWTH = 0.05
#: the places a queue can form, as the summaries name them
QUEUES = ("induction hold (min_gap)", "induction hold (returning parcels)", "merge waits")


def growth(ts: Sequence[float], waits: Sequence[float]) -> float:
    """Least-squares slope of ``waits`` [s] against ``ts`` [s] (NaN under 3 points or no
    spread): how much waiting a queue adds per second."""
    n = len(ts)
    if n < 3:
        return math.nan
    mt, mw = sum(ts) / n, sum(waits) / n
    var = sum((t - mt) ** 2 for t in ts)
    if var <= 0.0:
        return math.nan
    return sum((t - mt) * (w - mw) for t, w in zip(ts, waits, strict=True)) / var


def per_hour(times: Sequence[float]) -> float:
    """Events per hour over the span of ``times`` widened by one mean interval (NaN if < 2)."""
    if len(times) < 2:
        return math.nan
    span = max(times) - min(times)
    return 3600.0 * (len(times) - 1) / span if span > 0 else math.nan


def steady_window(parcels: Sequence, fill: float) -> dict | None:
    """The window and its counts. ``first_inductions``: new parcels whose front crossed X = 0
    in it (start <= t < end; a returning parcel's later pass is not counted again); ``sorts``:
    parcels sorted to a chute in it, whenever inducted. They differ by exact counts:
    ``sorts = first_inductions - still_on_line - ended_unsorted + from_before``, where
    ``still_on_line``: first inducted in the window and not ended by its end;
    ``ended_unsorted``: first inducted in it, rejected or failed in it; ``from_before``: first
    inducted before it, sorted in it. ``cohort_sorted``: first inducted in it and sorted,
    whenever. None when the induction ran no longer than ``fill`` (no steady state)."""
    firsts = [p.inducted_at for p in parcels if not math.isnan(p.inducted_at)]
    if len(firsts) < 2:
        return None
    start, end = min(firsts) + fill, max(firsts)
    if end <= start:
        return None

    def inside(t: float) -> bool:
        return start <= t < end

    new = [p for p in parcels if inside(p.inducted_at)]
    return {
        "start_s": start,
        "end_s": end,
        "fill_s": fill,
        "first_inductions": len(new),
        "sorts": sum(inside(p.sorted_at) for p in parcels),
        "still_on_line": sum(not p.ended_at < end for p in new),
        "ended_unsorted": sum(p.state != "sorted" and p.ended_at < end for p in new),
        "from_before": sum(p.inducted_at < start and inside(p.sorted_at) for p in parcels),
        "cohort_sorted": sum(p.state == "sorted" for p in new),
    }


def steady_state(
    parcels: Sequence,
    window: dict | None,
    offered_pcs_h: float,
    holds: Sequence[tuple[float, str, float]],
    merges: Sequence[tuple[float, float]],
) -> dict:
    """The steady state of a run: the cohort's fate and rates, inducted / offered, the queues'
    growth and the ``saturated`` flag with ``queue_at`` (places of :data:`QUEUES`).

    ``parcels``: the stream's parcels at the end of the run; ``window``: of
    :func:`steady_window`; ``offered_pcs_h``: the stream's arrivals per hour; ``holds``:
    (sim time, ``"min_gap"`` or ``"returning"``, seconds) of each hold of the stream;
    ``merges``: (return time, wait [s]) of each returning parcel merged. Without a window the
    queues and the rate in are judged over every parcel inducted and the cohort's figures are
    NaN (``cohort`` None)."""
    if window is None:
        start, end = -math.inf, math.inf
        cohort = []
    else:
        start, end = window["start_s"], window["end_s"]
        cohort = [p for p in parcels if start <= p.inducted_at < end]
    judged = cohort or [p for p in parcels if not math.isnan(p.inducted_at)]
    g_ind = growth([p.arrival for p in judged], [p.inducted_at - p.arrival for p in judged])
    m = [(t, w) for t, w in merges if start <= t < end]
    g_merge = growth([t for t, _ in m], [w for _, w in m])
    held = {c: sum((s for t, k, s in holds if k == c and start <= t < end), 0.0) for c in
            ("min_gap", "returning")}  # fmt: skip
    queue_at = []
    if g_ind > SATURATION_GROWTH:
        total = sum(held.values())
        for cause, name in zip(("min_gap", "returning"), QUEUES[:2], strict=True):
            if total > 0 and held[cause] >= 0.25 * total:
                queue_at.append(name)
    if g_merge > SATURATION_GROWTH:
        queue_at.append(QUEUES[2])
    rate_in = per_hour([p.inducted_at for p in judged])
    out = {
        "offered_pcs_h": offered_pcs_h,
        "inducted_pcs_h": rate_in,
        "inducted_over_offered": rate_in / offered_pcs_h if offered_pcs_h > 0 else math.nan,
        "sorted_pcs_h": math.nan,
        "out_over_in": math.nan,
        "cohort": None,
        "induction_delay_growth": g_ind,
        "merge_wait_growth": g_merge,
        "hold_s": held,
        "merge_wait_s": sum(w for _, w in m),
        "saturated": g_ind > SATURATION_GROWTH or g_merge > SATURATION_GROWTH,
        "queue_at": queue_at,
    }
    if window is None:
        return out
    hours = (end - start) / 3600.0
    n = len(cohort)
    fate = {s: sum(p.state == s for p in cohort) for s in ("sorted", "rejected", "failed")}
    fate["lost_with_unit"] = sum(p.state == "lost" for p in cohort)
    fate["on_line"] = n - sum(fate.values())
    out.update(
        inducted_pcs_h=n / hours,
        inducted_over_offered=n / hours / offered_pcs_h if offered_pcs_h > 0 else math.nan,
        sorted_pcs_h=fate["sorted"] / hours,
        out_over_in=fate["sorted"] / n if n else math.nan,
        cohort={"inducted": n, **fate},
    )
    return out
