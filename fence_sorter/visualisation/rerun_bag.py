"""A recorded run's bag as a Rerun recording (``fence-sorter rrd``): the sorting events at the
solver's resolution, the outcomes (their marks where each parcel was last seen) and the frames
of the scene, with :class:`~fence_sorter.visualisation.rerun_log.RerunLogger`."""

from __future__ import annotations

import math

from fence_sorter.recording import topics
from fence_sorter.stamps import time_to_sec
from fence_sorter.visualisation.frames import bag_frames, scene_from_bag
from fence_sorter.visualisation.rerun_keys import outcome_of
from fence_sorter.visualisation.rerun_layout import TIMELINE
from fence_sorter.visualisation.rerun_log import RerunLogger

FENCE_AT_REST = 1e-3  # |alpha_w| below this: the fence is at rest [rad]


def log_bag(contents, rec) -> RerunLogger:
    """Log a recorded run (read with :func:`fence_sorter.recording.bagread.read_bag`).

    The scene ends at the last outcome, or once the fence is back at rest after it (its
    stroke's return): the recorder keeps the fence's states until the run stops, and those
    idle seconds would stretch the viewer's time range past the run's last event."""
    from fence_sorter.analysis.events import SortEventData, risk_of  # lazy: loads rosbags
    from fence_sorter.analysis.run import OUTCOME_FIELDS

    logger = RerunLogger(rec, scene_from_bag(contents), series_every=1000, scene_every=1000)
    rr = logger.rr
    outcomes = {}
    for m in contents.by_topic(topics.SORT_OUTCOMES):
        outcomes[int(m.msg.parcel_id)] = {n: getattr(m.msg, n, math.nan) for n in OUTCOME_FIELDS}
    for m in contents.by_topic(topics.SORT_EVENTS):
        ev = SortEventData.from_msg(m.msg)
        o = outcomes.get(ev.parcel_id)
        logger.log_event(ev, risk_of(o) if o is not None else None)
    for pid, o in outcomes.items():  # a bag without /sort_events: the margins alone
        risk = risk_of(o)
        margin = min(risk["impact_speed_margin"], risk["accel_margin"])
        if pid not in logger.margins and math.isfinite(margin):
            logger.margins[pid] = margin
    pending = []  # (time, id, outcome), in time order
    for m in contents.by_topic(topics.SORT_OUTCOMES):
        o = m.msg
        t = time_to_sec(o.header.stamp)
        rec.set_time(TIMELINE, duration=t)
        rec.log("events/outcomes", rr.TextLog(f"parcel {o.parcel_id}: {o.reason}",
                                              level="INFO" if o.sorted else "WARN"))  # fmt: skip
        pending.append((t, int(o.parcel_id), outcome_of(_code_name(o))))
    pending.sort()
    t_end = bag_end(contents)
    last = None
    for t, fence, parcels in bag_frames(contents):
        while pending and pending[0][0] <= t:
            logger.log_outcome(*pending.pop(0))
        if t > t_end:
            break
        logger.log_frame(t, fence, parcels)
        last = (t, fence, parcels)
    for t, pid, outcome in pending:
        logger.log_outcome(t, pid, outcome)
    if last is not None and last[0] < t_end < math.inf:
        # a last frame at the end: the parcels left by then are gone, their marks remain
        t, fence, parcels = last
        left = [p for p in parcels if p.parcel_id not in logger.outcomes]
        logger.log_frame(t_end, fence, left)
    return logger


def bag_end(contents) -> float:
    """The last instant of a recorded run's view [s]: its last outcome, or the first fence
    state after it with the fence at rest if the fence was still moving (inf: no outcome)."""
    ends = [time_to_sec(m.msg.header.stamp) for m in contents.by_topic(topics.SORT_OUTCOMES)]
    if not ends:
        return math.inf
    t_out = max(ends)
    fences = sorted(
        (time_to_sec(m.msg.header.stamp), abs(m.msg.drive_angle))
        for m in contents.by_topic(topics.FENCE_STATE)
    )
    later = [(t, a) for t, a in fences if t > t_out]
    if not later or later[0][1] < FENCE_AT_REST:
        return t_out
    return next((t for t, a in later if a < FENCE_AT_REST), later[-1][0])


def _code_name(outcome_msg) -> str:
    """The name of a /sort_outcomes message's reason code (SORTED, NOT_DIVERTED, ...)."""
    code = int(outcome_msg.reason_code)
    for name in ("SORTED", "NOT_DIVERTED", "NO_FEASIBLE_COMMAND", "NO_COMMAND", "MISSED",
                 "REJECTED", "SOLVER_FAILURE"):  # fmt: skip
        if getattr(outcome_msg, name, None) == code:
            return name
    return "SORTED" if outcome_msg.sorted else "UNKNOWN"
