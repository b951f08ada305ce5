"""Rerun view of a line of fence units (no ROS): a top view of the whole belt with every unit
and the parcels, and per-unit time plots, sampled from a running
:class:`~fence_sorter.line.multi_unit.LinePlant` (its ``observers``) every ``period`` of sim
time.

Frame "line" (X along the belt from the induction scan line, Y across it from the right
border); the top view draws it in view coordinates ``(X, -Y)`` like the single-unit view.
Entity paths:

- static: ``top/conveyor/belt``, ``top/conveyor/borders``, ``top/induction``, ``top/belt_end``
  (the recirculation and the reject chute), per unit ``top/units/<name>/chute`` (its box, a
  mark per destination it serves in that destination's colour, labelled) and
  ``top/units/<name>/axis`` (the fence axis, labelled with the unit's name);
- per sample: ``top/units/<name>/fence`` (the fence at its pose and side, deflected: one row
  per sample), ``top/parcels`` (the rotated footprints, labelled ``<id> <destination>``, the
  labels hidden; coloured by destination on the belt, by damage margin once sorted: a sorted
  parcel stays SORTED_SHOWN s at its pose at the outcome, C_s on the chute edge),
  ``top/parcel_ids`` (their ids, dark, under them), ``top/loop/parcels`` (the parcels on the
  recirculation loop: dots in their destinations' colours on a lane above the belt, static
  ``top/loop``, from the belt's end back to the induction over the loop's transit time) and
  ``top/counters`` (sorted, on the line, rejected, failed);
- ``plots/alpha_w/<name>`` [rad] and ``plots/contact/<name>`` (the unit's largest N at the
  sample [kN]; an impact lasts a few ms, so the samples miss most peaks) in the unit's colour,
  and ``plots/contact/<name>/peak``: each sorted parcel's peak N from its solve, at its
  outcome.

A sample is one call of :meth:`LineRerunLogger.add` (fences, plots and parcel frames in the
line frame): :meth:`LineRerunLogger.sample` takes it from a LinePlant, the live view of a line
over DDS (``nodes/line_viewer.py``) from the units' view messages.
"""

from __future__ import annotations

import math

import numpy as np

from fence_sorter.capacity.constraints import damage_risk
from fence_sorter.line.handoff import Sorted
from fence_sorter.line.routing import to_line
from fence_sorter.line.unit import ID_STRIDE
from fence_sorter.visualisation.frames import CHUTE_DEPTH, CHUTE_LENGTH, ParcelFrame
from fence_sorter.visualisation.rerun_layout import (
    ALPHA_AXIS,
    FORCE_PLOT_UNIT,
    TIMELINE,
    TOP,
    _rr,
    open_recording,
    time_plot,
)
from fence_sorter.visualisation.rerun_log import LABEL_COLOR, _footprints, margin_color

__all__ = [
    "DESTINATION_COLORS",
    "LINE_CONTACT_AXIS",
    "LineRerunLogger",
    "UNIT_COLORS",
    "chute_box",
    "fence_strip",
    "line_blueprint",
    "open_recording",
    "parcel_frame",
    "parcel_label",
]

#: destination colours (in the order of the line file's destinations, then again): none is
#: the belt's grey, the borders' yellow, the fence's orange or a damage margin's red-green
DESTINATION_COLORS = (
    (31, 119, 180), (148, 103, 189), (23, 190, 207), (227, 119, 194),
    (140, 86, 75), (40, 40, 140), (200, 0, 200), (0, 128, 128),
)  # fmt: skip
#: each unit's colour in the plots (units in belt order, then again): dark and neutral, none
#: a destination's colour, the fence's orange or a damage margin's red-green
UNIT_COLORS = ((20, 20, 20), (130, 130, 130), (128, 128, 0), (100, 50, 0))
UNIT_COLOR_NAMES = ("black", "grey", "olive", "brown")
FENCE_COLOR = (230, 80, 30)
BELT_COLOR = (70, 70, 70)
BORDER_COLOR = (220, 220, 60)
CHUTE_COLOR = (50, 100, 200)
INDUCTION_COLOR = (255, 60, 60)
#: the contact-force plot's range [kN] (single-digit tick labels; a stiff fence's impact
#: peaks reach 2.5 kN on four_units.yaml at 3000 pcs/h)
LINE_CONTACT_AXIS = (-0.25, 4.0)
#: a sorted parcel stays in the view this long at its pose at the outcome [s]
SORTED_SHOWN = 2.0
#: the recirculation loop's lane in the top view: this far beyond the far chutes [m]; a
#: parcel on it is a dot moving from the belt's end back to the induction over transit_time
LOOP_GAP = 0.6
LOOP_RADIUS = 0.15  # [m]
#: the running counters' line: this far above the loop's lane [m]
COUNTERS_GAP = 1.2
#: the viewer draws a point's label below the point: ids sit this far below their parcel's
#: centre [m] (the line's top view draws about 50 px per metre)
ID_DROP = 0.3
LINE_CHAR_WIDTH = 0.12  # a label's width per character in the line's top view [m]


def loop_lane_y(width: float) -> float:
    """View y of the recirculation loop's lane (above the chutes beyond the far border)."""
    return -width - CHUTE_DEPTH - LOOP_GAP


def loop_x(length: float, transit_time: float, t: float, return_time: float) -> float:
    """X [m] of a parcel on the loop at ``t`` [s]: from the belt's end (``length``) when it
    left back to the induction (0) at ``return_time``."""
    if transit_time <= 0.0:
        return 0.0
    return length * min(max((return_time - t) / transit_time, 0.0), 1.0)


def counters_text(counts: dict) -> str:
    """The counters' line: sorted, on the line (on the belt, on the loop), rejected, failed."""
    on_line = counts.get("belt", 0) + counts.get("loop", 0)
    return (
        f"sorted {counts.get('sorted', 0)}    on the line {on_line} (belt "
        f"{counts.get('belt', 0)}, loop {counts.get('loop', 0)})    rejected "
        f"{counts.get('rejected', 0)}    failed {counts.get('failed', 0)}"
    )


def chute_box(position: float, mirrored: bool, width: float) -> tuple[float, float, float, float]:
    """A unit's chute in the line frame: (x0, y0, x1, y1) [m]: from the fence axis
    CHUTE_LENGTH downstream, beyond the belt border opposite the fence (Y > s on a right-side
    unit, Y < 0 on a mirrored one) CHUTE_DEPTH deep."""
    if mirrored:
        return position, -CHUTE_DEPTH, position + CHUTE_LENGTH, 0.0
    return position, width, position + CHUTE_LENGTH, width + CHUTE_DEPTH


def _color_text(k: int) -> str:
    return UNIT_COLOR_NAMES[k % len(UNIT_COLOR_NAMES)]


def line_blueprint(line, paused: bool = False):
    """The line's layout: the top view of the whole belt wide on top (framed on the belt, the
    chutes and the induction), the per-unit plots of alpha_w and N under it."""
    import rerun.blueprint as rrb  # lazy: Rerun (0.5 s), only to log

    colours = ", ".join(f"{u.name} {_color_text(k)}" for k, u in enumerate(line.units))
    margin = 0.6
    x_range = (-1.2 - margin, line.length + margin)
    y_range = (loop_lane_y(line.width) - COUNTERS_GAP - margin, CHUTE_DEPTH + margin)
    parts = [
        rrb.Vertical(
            rrb.Spatial2DView(
                name="line, top view [m], belt running to the right: parcels (ids) by "
                "destination (chute marks), sorted ones by damage margin (green safe, red over "
                "a limit); recirculation loop above",
                origin=TOP,
                visual_bounds=rrb.VisualBounds2D(x_range=x_range, y_range=y_range),
            ),
            time_plot(f"drive angle alpha_w [rad]: {colours}", "plots/alpha_w", ALPHA_AXIS),
            time_plot(
                f"contact force N [kN], sampled: lines, a sorted parcel's peak: dots; {colours}",
                "plots/contact",
                LINE_CONTACT_AXIS,
            ),
            row_shares=[2, 1, 1],
        )
    ]
    if paused:
        parts.append(rrb.TimePanel(timeline=TIMELINE, play_state="paused", state="collapsed"))
    return rrb.Blueprint(*parts, collapse_panels=True)


def parcel_label(pid: int, destination: str) -> str:
    """A parcel's label in the view: ``<line id> <destination>``."""
    return f"{pid} {destination}"


def fence_strip(us, width: float, node_x, node_y) -> np.ndarray:
    """A unit's fence (its nodes in the unit's frame) as a strip in the top view's
    coordinates (X, -Y of the line frame)."""
    x, y, _ = to_line(us.position, us.mirrored, width, np.asarray(node_x), np.asarray(node_y),
                      0.0)  # fmt: skip
    return np.column_stack((x, -y))


def parcel_frame(us, width: float, pid: int, spec, x: float, y: float, yaw: float) -> ParcelFrame:
    """A parcel at C_s (x, y, yaw) in unit ``us``'s frame as a ParcelFrame in the line frame
    (its box centre from the C_s offsets of ``spec``, a ParcelSpec as the unit's simulation
    has it: sizes, ``cog_offset_x``/``_y`` in the unit's frame)."""
    c, sn = math.cos(yaw), math.sin(yaw)
    cx = x - c * spec.cog_offset_x + sn * spec.cog_offset_y
    cy = y - sn * spec.cog_offset_x - c * spec.cog_offset_y
    lx, ly, lyaw = to_line(us.position, us.mirrored, width, cx, cy, yaw)
    return ParcelFrame(pid, lx, ly, lyaw, 0.0, 0.0, lx, ly, spec.length_a, spec.width_b,
                       spec.height)  # fmt: skip


class LineRerunLogger:
    """Samples a LinePlant every ``period`` of sim time (:meth:`observe`, one of the plant's
    observers) into a recording; frames are buffered and sent as columns every
    ``flush_every`` samples and on :meth:`close`."""

    def __init__(self, rec, line, period: float = 0.02, flush_every: int = 500) -> None:
        self.rr = _rr()
        self.rec = rec
        self.line = line
        self.period = float(period)
        self.flush_every = max(int(flush_every), 1)
        self.samples = 0
        self._last = 0.0  # sim time of the last sample [s]
        self._next = self.period
        self.dest_color = {
            d: DESTINATION_COLORS[k % len(DESTINATION_COLORS)]
            for k, d in enumerate(line.destinations)
        }
        self.profile = line.planner.profile
        # parcel id -> (time sorted, ParcelFrame at the outcome, label, colour)
        self._sorted: dict[int, tuple[float, ParcelFrame, str, tuple]] = {}
        self._reset()
        self._log_static()

    def _reset(self) -> None:
        self._t: list[float] = []
        self._fences: list[list[np.ndarray]] = [[] for _ in self.line.units]
        self._counts: list[int] = []
        self._strips: list[np.ndarray] = []
        self._labels: list[str] = []
        self._colors: list[tuple] = []
        self._ids: list[np.ndarray] = []  # per sample: the id labels' points
        self._loop_counts: list[int] = []
        self._loop_at: list[tuple] = []
        self._loop_labels: list[str] = []
        self._loop_colors: list[tuple] = []
        self._counters: list[str] = []
        self._alpha: list[list[float]] = [[] for _ in self.line.units]
        self._force: list[list[float]] = [[] for _ in self.line.units]

    # -- static ----------------------------------------------------------------------------
    def _log_static(self) -> None:
        rr, rec, ln = self.rr, self.rec, self.line
        s, length = ln.width, ln.length
        rec.log(
            f"{TOP}/conveyor/belt",
            rr.Boxes2D(centers=[(0.5 * length, -0.5 * s)], sizes=[(length, s)],
                       colors=[BELT_COLOR], draw_order=0.0),
            static=True,
        )  # fmt: skip
        rec.log(
            f"{TOP}/conveyor/borders",
            rr.LineStrips2D([[(0.0, 0.0), (length, 0.0)], [(0.0, -s), (length, -s)]],
                            colors=[BORDER_COLOR], radii=0.02, draw_order=1.0),
            static=True,
        )  # fmt: skip
        rec.log(
            f"{TOP}/induction",
            rr.LineStrips2D([[(0.0, 0.0), (0.0, -s)]], colors=[INDUCTION_COLOR], radii=0.03,
                            draw_order=2.0),
            static=True,
        )  # fmt: skip
        # the texts as dark labels of points of their own (a label takes its entity's colour)
        texts = [
            ((0.0, -s - 0.35), "induction"),
            ((length - 1.8, 0.45),
             f"end: loop {ln.transit_time:g} s\n{ln.reject_chute} after {ln.max_passes} passes"),
        ]  # fmt: skip
        rec.log(
            f"{TOP}/belt_end",
            rr.LineStrips2D([[(length, 0.0), (length, -s)]], colors=[INDUCTION_COLOR],
                            radii=0.03, draw_order=2.0),
            static=True,
        )  # fmt: skip
        for u in ln.units:
            x0, y0, x1, y1 = chute_box(u.position, u.mirrored, s)
            base = f"{TOP}/units/{u.name}"
            rec.log(
                f"{base}/chute",
                rr.Boxes2D(centers=[(0.5 * (x0 + x1), -0.5 * (y0 + y1))],
                           sizes=[(x1 - x0, y1 - y0)], colors=[CHUTE_COLOR], radii=0.02,
                           draw_order=0.5),
                static=True,
            )  # fmt: skip
            # a mark per destination inside the chute, in its colour: the key of the parcels'
            n = len(u.destinations)
            ym = -0.5 * (y0 + y1)
            marks = [(x0 + (j + 0.5) * (x1 - x0) / n - 0.2, ym) for j in range(n)]
            rec.log(
                f"{base}/destinations",
                rr.Points2D(marks, colors=[self.dest_color[d] for d in u.destinations],
                            radii=0.12, draw_order=2.5),
                static=True,
            )  # fmt: skip
            texts += [((m[0] + 0.38, ym), d) for m, d in zip(marks, u.destinations, strict=True)]
            # the fence axis, its name outside the fence's border
            ay = -(s if u.mirrored else 0.0)
            rec.log(
                f"{base}/axis",
                rr.Points2D([(u.position, ay)], colors=[LABEL_COLOR], radii=0.06,
                            draw_order=6.5),
                static=True,
            )  # fmt: skip
            texts.append(((u.position - 0.3, ay + (-0.4 if u.mirrored else 0.4)), u.name))
        # the recirculation loop: a lane from the belt's end back to the induction
        ly = loop_lane_y(s)
        rec.log(
            f"{TOP}/loop",
            rr.Arrows2D(origins=[(length, ly)], vectors=[(-length, 0.0)], colors=[(150, 150, 150)],
                        radii=0.03, draw_order=1.0),
            static=True,
        )  # fmt: skip
        texts.append(((0.5 * length, ly - 0.6),
                      f"recirculation loop: {ln.transit_time:g} s from the end back to the "
                      "induction"))  # fmt: skip
        rec.log(
            f"{TOP}/labels",
            rr.Points2D([p for p, _ in texts], colors=[LABEL_COLOR], radii=0.001,
                        labels=[t for _, t in texts], show_labels=True, draw_order=8.0),
            static=True,
        )  # fmt: skip
        for k, u in enumerate(ln.units):
            colour = [UNIT_COLORS[k % len(UNIT_COLORS)]]
            rec.log(
                f"{TOP}/units/{u.name}/fence",
                rr.LineStrips2D.from_fields(colors=[FENCE_COLOR], radii=0.03, draw_order=4.0),
                static=True,
            )
            for plot, name in (("alpha_w", "alpha_w"), ("contact", "N")):
                rec.log(
                    f"plots/{plot}/{u.name}",
                    rr.SeriesLines(names=f"{name} {u.name}", colors=colour),
                    static=True,
                )
            rec.log(
                f"plots/contact/{u.name}/peak",
                rr.SeriesPoints(names=f"peak N {u.name}", colors=colour, markers="circle",
                                marker_sizes=3.0),
                static=True,
            )  # fmt: skip
        rec.log(
            f"{TOP}/parcels",
            rr.LineStrips2D.from_fields(radii=0.05, show_labels=False, draw_order=3.0),
            static=True,
        )
        styles = {
            f"{TOP}/parcel_ids": rr.Points2D.from_fields(
                colors=[LABEL_COLOR], radii=0.0, show_labels=True, draw_order=7.0
            ),
            f"{TOP}/loop/parcels": rr.Points2D.from_fields(
                radii=LOOP_RADIUS, show_labels=True, draw_order=3.0
            ),
            f"{TOP}/counters": rr.Points2D.from_fields(
                colors=[LABEL_COLOR], radii=0.0, show_labels=True, draw_order=8.0
            ),
        }
        for entity, style in styles.items():
            rec.log(entity, style, static=True)

    # -- samples ---------------------------------------------------------------------------
    def observe(self, plant, records) -> None:
        """A LinePlant observer: note the step's sorts, and sample when a period is due."""
        for rec in records:
            if isinstance(rec, Sorted):
                self._note_sorted(plant, plant.units[rec.unit], rec)
        if plant.t + 1e-9 >= self._next:
            self.sample(plant)
            self._next += self.period * max(1, math.floor((plant.t + 1e-9 - self._next)
                                                          / self.period) + 1)  # fmt: skip

    def _note_sorted(self, plant, u, rec: Sorted) -> None:
        """A sorted parcel: its pose at its outcome from its stroke's solve (which runs on
        for the fence), its damage margin colour, and its stroke's peak N on the unit's plot."""
        p = plant.by_id.get(rec.parcel_id)
        if p is None:
            return
        local = p.pid * ID_STRIDE + p.passes
        st = next((s for s in u.line.strokes if s.parcel.spec.parcel_id == local), None)
        if st is None or st.parcel.outcome is None or st.tap.cur is None:
            return
        out = st.parcel.outcome
        y, _ = st.tap.at(out.t - st.t_start)
        frame = self._frame(p.pid, u.spec, st.parcel.spec, float(y[0]), float(y[1]), float(y[2]))
        risk = damage_risk(out.impact_normal_speed, out.peak_normal_accel, self.profile)
        margin = min(risk.impact_speed_margin, risk.accel_margin)
        colour = margin_color(margin) if math.isfinite(margin) else self.dest_color[p.destination]
        self._sorted[p.pid] = (out.t, frame, parcel_label(p.pid, p.destination), colour)
        if math.isfinite(out.peak_normal_force):
            self.rec.set_time(TIMELINE, duration=float(out.t))
            self.rec.log(
                f"plots/contact/{u.spec.name}/peak",
                self.rr.Scalars(float(out.peak_normal_force) / FORCE_PLOT_UNIT),
            )

    def _frame(self, pid: int, us, spec, x: float, y: float, yaw: float) -> ParcelFrame:
        return parcel_frame(us, self.line.width, pid, spec, x, y, yaw)

    def sample(self, plant) -> None:
        """The line at the plant's time: fences, parcels, per-unit alpha_w and N."""
        t = plant.t
        fences, alphas, forces = [], [], []
        in_stroke: dict[int, ParcelFrame] = {}
        for k, u in enumerate(plant.units):
            snap = u.line.snapshot()
            f = snap.fence
            fences.append(fence_strip(u.spec, self.line.width, f.node_x, f.node_y))
            alphas.append(float(f.drive_angle))
            forces.append(max((q.contact_normal_force for q in snap.parcels), default=0.0))
            for q in snap.parcels:
                p = plant.by_id.get(q.parcel_id // ID_STRIDE)
                if p is None or p.stroke_unit != k or q.parcel_id % ID_STRIDE != p.passes:
                    continue
                spec = u.line.parcels[q.parcel_id].spec if q.parcel_id in u.line.parcels else None
                if spec is not None:
                    in_stroke[p.pid] = self._frame(p.pid, u.spec, spec, q.x, q.y, q.yaw)
        frames, labels, colors = [], [], []
        for p in plant.live:
            if p.state != "belt" or p.track is None:
                continue
            fr = in_stroke.get(p.pid)
            if fr is None:
                tr = p.track
                pts = tr.corners(t)
                cx = sum(c[0] for c in pts) / 4.0
                cy = sum(c[1] for c in pts) / 4.0
                fr = ParcelFrame(p.pid, cx, cy, tr.yaw, 0.0, 0.0, cx, cy, tr.length_a,
                                 tr.width_b, p.spec.height)  # fmt: skip
            frames.append(fr)
            labels.append(parcel_label(p.pid, p.destination))
            colors.append(self.dest_color[p.destination])
        ln = self.line
        loop = [
            (p.pid, loop_x(ln.length, ln.transit_time, t, p.return_time),
             self.dest_color[p.destination])
            for p in plant.live
            if p.state == "loop"
        ]  # fmt: skip
        counts: dict[str, int] = {}
        for p in plant.parcels:
            counts[p.state] = counts.get(p.state, 0) + 1
        self.add(t, fences, alphas, forces, frames, labels, colors, loop=loop, counts=counts)

    def add(
        self,
        t: float,
        fences: list[np.ndarray],
        alphas: list[float],
        forces: list[float],
        frames: list[ParcelFrame],
        labels: list[str],
        colors: list[tuple],
        loop: list[tuple] | None = None,
        counts: dict | None = None,
    ) -> None:
        """One sample of the line at sim time ``t``, whoever took it (a LinePlant's
        :meth:`sample`, or the live view of a line over DDS): per unit in the line's order its
        fence (:func:`fence_strip`), alpha_w [rad] and largest contact force N [N]; the
        parcels on the belt or in a stroke as frames in the line frame (:func:`parcel_frame`)
        with their labels and colours. The sorted parcels noted within SORTED_SHOWN are
        added here. ``loop``: (id, X [m], colour) of each parcel on the recirculation loop;
        ``counts``: parcels per state (sorted, belt, loop, rejected, failed) for the
        counters."""
        self._last = t
        self._t.append(t)
        for k in range(len(self.line.units)):
            self._fences[k].append(fences[k])
            self._alpha[k].append(float(alphas[k]))
            self._force[k].append(float(forces[k]) / FORCE_PLOT_UNIT)
        frames, labels, colors = list(frames), list(labels), list(colors)
        for pid, (ts, fr, label, colour) in list(self._sorted.items()):
            if t - ts > SORTED_SHOWN:
                del self._sorted[pid]
                continue
            frames.append(fr)
            labels.append(label)
            colors.append(colour)
        self._counts.append(len(frames))
        if frames:
            self._strips.append(_footprints(frames))
        self._ids.append(
            np.array([(f.center_x, -f.center_y + ID_DROP) for f in frames]).reshape(-1, 2)
        )
        ly = loop_lane_y(self.line.width)
        loop = list(loop or [])
        self._loop_counts.append(len(loop))
        self._loop_at += [(x, ly) for _, x, _ in loop]
        self._loop_labels += [str(pid) for pid, _, _ in loop]
        self._loop_colors += [c for _, _, c in loop]
        self._counters.append(counters_text(counts) if counts is not None else "")
        self._labels += labels
        self._colors += colors
        self.samples += 1
        if self.samples % self.flush_every == 0:
            self.flush()

    def flush(self) -> None:
        rr, send = self.rr, self.rec.send_columns
        if not self._t:
            return
        index = [rr.TimeColumn(TIMELINE, duration=self._t)]
        ones = [1] * len(self._t)
        for k, u in enumerate(self.line.units):
            send(f"{TOP}/units/{u.name}/fence", index,
                 rr.LineStrips2D.columns(strips=self._fences[k]).partition(ones))  # fmt: skip
            send(f"plots/alpha_w/{u.name}", index, rr.Scalars.columns(scalars=self._alpha[k]))
            send(f"plots/contact/{u.name}", index, rr.Scalars.columns(scalars=self._force[k]))
        send(
            f"{TOP}/parcel_ids",
            index,
            rr.Points2D.columns(
                positions=np.concatenate(self._ids),
                labels=[lb.split()[0] for lb in self._labels],
            ).partition([len(a) for a in self._ids]),
        )
        send(
            f"{TOP}/loop/parcels",
            index,
            rr.Points2D.columns(
                positions=np.array(self._loop_at, dtype=float).reshape(-1, 2),
                colors=np.array(self._loop_colors, dtype=np.uint8).reshape(-1, 3),
                labels=self._loop_labels,
            ).partition(self._loop_counts),
        )
        if any(self._counters):
            y = loop_lane_y(self.line.width) - COUNTERS_GAP
            # a label is centred on its point: its text starts at the induction
            at = [(0.5 * LINE_CHAR_WIDTH * len(c), y) for c in self._counters]
            send(
                f"{TOP}/counters",
                index,
                rr.Points2D.columns(positions=at, labels=self._counters),
            )
        strips = np.concatenate(self._strips) if self._strips else np.zeros((0, 5, 2))
        send(
            f"{TOP}/parcels",
            index,
            rr.LineStrips2D.columns(
                strips=strips,
                colors=np.array(self._colors, dtype=np.uint8).reshape(-1, 3),
                labels=self._labels,
            ).partition(self._counts),
        )
        self._reset()

    def close(self, plant=None) -> None:
        """Send what is buffered; with ``plant``, first a last sample at its time if the run
        ended between two samples (the last sorts are in the recording)."""
        if plant is not None and (not self._last or plant.t > self._last + 1e-9):
            self.sample(plant)
        self.flush()
        self.rec.flush()
        self.rec.disconnect()
