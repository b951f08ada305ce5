"""The line's per-parcel records: what each unit decided for each parcel on each pass, the
stroke that sorted it (or its last one) with the delivered figures against the limits
(10)-(12), and where it ended.

The plant tells a :class:`ParcelLog` each decision as it happens (:meth:`ParcelLog.decided`,
:meth:`ParcelLog.record`); :func:`parcel_rows` reads it with the units' stroke records at the
end of a run. The stroke's columns and margins are :func:`~fence_sorter.capacity.delivered.
delivered_row`'s, the single-unit runs' per-parcel table. Columns: :data:`COLUMNS`
(docs/guide/line.md, "Per-parcel records").
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

from fence_sorter.capacity.delivered import ROW_COLUMNS, delivered_row
from fence_sorter.codes import OutcomeCode
from fence_sorter.line.handoff import Failed, HandOff, Sorted

__all__ = ["COLUMNS", "ParcelLog", "parcel_rows", "write_rows"]

#: the line's own columns, then the stroke's (:data:`~fence_sorter.capacity.delivered.
#: ROW_COLUMNS` less the parcel id and the stroke's outcome flags)
LINE_COLUMNS = [
    "parcel_id", "destination", "state", "chute", "recirculations", "no_read", "arrival_s",
    "inducted_s", "ended_s", "decisions", "stroke_unit", "stroke_outcome",
    "in_other_strokes_sector",
]  # fmt: skip
STROKE_COLUMNS = [
    c for c in ROW_COLUMNS if c not in ("parcel_id", "outcome", "sorted", "failed", "yaw_rad")
]
COLUMNS = LINE_COLUMNS + STROKE_COLUMNS
#: a parcel's ``state`` at the end of the run, from the plant's state of it
STATES = {
    "new": "not_inducted", "scheduled": "on_belt", "belt": "on_belt", "loop": "in_loop",
    "sorted": "sorted", "rejected": "rejected", "failed": "failed", "lost": "lost_with_unit",
}  # fmt: skip


class ParcelLog:
    """The decisions of the units, per parcel: (pass, unit, what) in the order they came."""

    def __init__(self, names: Sequence[str]):
        self.names = list(names)
        self.entries: dict[int, list[list]] = {}

    def decided(self, pid: int, passes: int, unit: int, refusal: str, reason: str,
                booked: bool) -> None:  # fmt: skip
        """A unit answered a hand-off: refused it, booked a stroke or declined with ``reason``."""
        what = (
            f"refused:{refusal}" if refusal else "booked" if booked
            else f"declined:{reason or 'command_refused'}"
        )  # fmt: skip
        self.entries.setdefault(pid, []).append([passes, self.names[unit], what])

    def record(self, pid: int, passes: int, unit: int, rec: object, in_stroke: bool) -> None:
        """A record of ``unit`` for the parcel: a stroke's end (``in_stroke``: sorted, failed,
        or missed, the hand-off after it), or a hand-off it sent for a parcel it never got
        (lost on its upstream link: passed on from the line's prediction)."""
        name = self.names[unit]
        log = self.entries.setdefault(pid, [])
        if in_stroke:
            end = "sorted" if isinstance(rec, Sorted) else (
                "failed" if isinstance(rec, Failed) else "missed"
            )  # fmt: skip
            for e in reversed(log):
                if e[1] == name and e[2] == "booked":
                    e[2] = f"booked>{end}"
                    return
        elif isinstance(rec, HandOff) and not any(e[0] == passes and e[1] == name for e in log):
            log.append([passes, name, "lost"])

    def text(self, pid: int) -> str:
        """The compact field: ``unit=what`` per decision, passes separated by `` | ``."""
        passes: dict[int, list[str]] = {}
        for k, name, what in self.entries.get(pid, []):
            passes.setdefault(k, []).append(f"{name}={what}")
        return " | ".join(" ".join(v) for _, v in sorted(passes.items()))


def parcel_rows(plant) -> list[dict]:
    """One row per parcel of ``plant`` (a :class:`~fence_sorter.line.multi_unit.LinePlant`
    after its run), columns :data:`COLUMNS`. A unit without stroke records (one in a process
    of its own) leaves its strokes' columns empty (NaN)."""
    strokes: dict[int, tuple[str, object, object]] = {}
    intruded: dict[int, int] = {}
    line_profile = plant.spec.planner.profile
    for u, name in zip(plant.units, plant.names, strict=True):
        prof = getattr(u, "profile", line_profile)  # the limits the unit judges against
        for r in getattr(u, "stroke_records", ()):
            prev = strokes.get(r.parcel_id)
            if prev is None or prev[1].code is not OutcomeCode.SORTED:
                strokes[r.parcel_id] = (name, r, prof)  # the sorting stroke, else the last
        for other, _ in getattr(u, "intruded", ()):
            intruded[other] = intruded.get(other, 0) + 1
    rows = []
    for p in plant.parcels:
        unit, r, prof = strokes.get(p.pid, ("", None, line_profile))
        outcome, command = {}, None
        parcel = {"mass": p.spec.mass, "length_a": p.spec.length_a, "width_b": p.spec.width_b}
        if r is not None:
            outcome = {
                "reason_name": r.code.name, "sorted": r.code is OutcomeCode.SORTED,
                "impact_normal_speed": r.impact_normal_speed,
                "peak_normal_accel": r.peak_normal_accel, "exit_speed_y": r.exit_speed_y,
            }  # fmt: skip
            command = {"r_s": r.r_s, "t1": r.t1, "alpha_k": r.alpha_k}
            for k, x in zip(("impact_speed", "peak_accel", "exit_speed"), r.planned, strict=True):
                command[f"predicted_{k}"] = x
            parcel["yaw"] = r.yaw
        d = delivered_row(p.pid, outcome, command, parcel, prof, plant.v)
        loops = p.passes - (p.state == "rejected")
        row = {
            "parcel_id": p.pid, "destination": p.destination, "state": STATES[p.state],
            "chute": p.end, "recirculations": max(loops, 0), "no_read": p.ever_no_read,
            "arrival_s": p.arrival, "inducted_s": p.inducted_at, "ended_s": p.ended_at,
            "decisions": plant.log.text(p.pid), "stroke_unit": unit,
            "stroke_outcome": r.code.name.lower() if r is not None else "",
            "in_other_strokes_sector": intruded.get(p.pid, 0),
        }  # fmt: skip
        row.update({c: d[c] for c in STROKE_COLUMNS})
        rows.append(row)
    return rows


def _cell(v: object) -> object:
    if isinstance(v, float) and math.isnan(v):
        return ""
    if isinstance(v, list):
        return ";".join(map(str, v))
    return v


def write_rows(rows: list[dict], path: str | Path) -> None:
    """Write the rows to ``path``: Parquet for ``*.parquet`` (pyarrow), else CSV (empty cell:
    none, NaN; ``over_limits`` as ``10;12``)."""
    path = Path(path)
    if path.suffix == ".parquet":
        # lazy: pyarrow's Parquet module takes 1.3 s, only a Parquet file needs it
        import pyarrow as pa
        import pyarrow.parquet as pq

        flat = [{**r, "over_limits": ";".join(map(str, r["over_limits"]))} for r in rows]
        pq.write_table(pa.Table.from_pylist(flat), path)
        return
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({c: _cell(r[c]) for c in COLUMNS})
