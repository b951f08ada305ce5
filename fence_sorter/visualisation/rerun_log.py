"""Rerun views of the twin (no ROS): conveyor, chute, scan line, the fence polyline with its
real deflection, parcels as one Boxes3D batch labelled with their ids, contact force arrows, and
time series (N, N_stiff, tip deflection, alpha_w, parcel speeds) on the ``sim_time`` timeline.

The logger is driven by plain frames (:class:`FenceFrame`, :class:`ParcelFrame`, in
``visualisation/frames.py``), made from the line's snapshots (:func:`frames_from_snapshot`, used
live by the simulator) or from a recorded bag (``visualisation/rerun_bag.py``, ``fence-sorter
rrd``); the recording stream and its layout are ``visualisation/rerun_layout.py``'s. Entity paths:

- ``world/conveyor/belt``, ``world/conveyor/borders``, ``world/chute``, ``world/scan_line``
  (static), ``world/fence``, ``world/parcels``, ``world/contact_forces``;
- ``top/...``: the same in 2D for the top view (parcels as their rotated footprints), in view
  coordinates ``(x, -y)`` (a 2D view draws y downwards; so y0, towards the chute, points up);
- ``plots/contact/<id>/N`` and ``.../N_stiff`` [kN], ``plots/fence/tip_deflection`` (the
  tip's yield -w [cm], positive under load),
  ``plots/fence/alpha_w`` [rad], ``plots/speed/<id>`` [m/s] at the publish rate;
- per sorting event at the solver's resolution (:meth:`RerunLogger.log_event`):
  ``plots/contact/<id>/N_steps``, ``.../N_stiff_course`` [kN],
  ``plots/fence/tip_deflection/steps/<id>`` [cm]; ``damage/w_n`` [m/s], ``damage/a_N``
  [10^2 m/s^2], ``damage/N`` [kN] (``value`` and ``limit``): each parcel's impact against the
  limits at its outcome time.

Frame "sorter" (REP-103, z up): x0 along the belt, y0 across it towards the chute. The default
blueprint opens on the top view with the time series beside it (the 3D view in a tab behind,
the damage-risk plots in a tab behind the time series). A parcel's outline is coloured by what
the scan decided (to divert, to pass); where it was last seen, its outcome mark
(``top/outcomes``: sorted, passed, missed, failed); its damage margin colours its damage mark
under the belt. The two colour schemes, their legend, a scale bar and the belt's direction are
``visualisation/rerun_keys.py``'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fence_sorter.visualisation.frames import (
    FenceFrame,
    ParcelFrame,
    SceneGeometry,
    bag_frames,
    frames_from_snapshot,
    scene_from_bag,
)
from fence_sorter.visualisation.rerun_keys import (
    LABEL_COLOR,
    LABEL_DROP,
    MARGIN_COLORS,
    MARGIN_RANGE,
    OUTCOME_COLORS,
    PARCEL_COLORS,
    log_keys,
    log_outcome_marks,
    margin_color,
)
from fence_sorter.visualisation.rerun_layout import (
    ACCEL_PLOT_UNIT,
    ALPHA_AXIS,
    APP_ID,
    CONTACT_AXIS,
    DEFLECTION_AXIS,
    DEFLECTION_PLOT_UNIT,
    FORCE_PLOT_UNIT,
    RISK,
    RISK_MARKS_PER_ROW,
    RISK_ROW,
    RISK_ROWS_FRAMED,
    SPEED_AXIS,
    SPEED_AXIS_MAX,
    TIMELINE,
    TOP,
    _rr,
    blueprint,
    camera_position,
    camera_target,
    open_recording,
    risk_mark_position,
    top_view_bounds,
)

FENCE_Z = 0.05  # height the fence polyline is drawn at [m]
FORCE_SCALE = 1.0 / 1000.0  # contact arrow length per newton [m/N]
#: a parcel's outline (and its speed's line) by what the scan decided; its outcome mark's
#: colour once it has left (``rerun_keys.py``: one scheme, none of the damage margins' colours)
DIVERT_COLOR = PARCEL_COLORS["to divert"]
PASS_COLOR = PARCEL_COLORS["to pass"]
#: colours the plots' titles name (no legends): N and N_stiff, solver steps and samples
N_COLOR = (40, 110, 220)
N_STIFF_COLOR = (235, 120, 20)
STEPS_COLOR = (40, 110, 220)
SAMPLED_COLOR = (120, 120, 120)
ALPHA_COLOR = (200, 50, 50)
RISK_TICKS = (0.0, 0.5, 1.0)  # the chart's y scale: value / limit


class RerunLogger:
    """Logs the scene once and then one frame per call of :meth:`log_frame`.

    Frames are buffered and sent as columns (one ``send_columns`` per entity): the scene
    (fence, parcels, force arrows, in 3D and in the top view) every ``scene_every`` frames, the
    time series every ``series_every`` frames, and everything on :meth:`flush`/:meth:`close`.
    One call per entity and batch instead of one per frame is most of the saving; a live
    viewer sees the scene up to ``scene_every`` frames late (the live child uses 5 with a
    viewer, 0.1 s at 50 Hz; smaller batches make a larger .rrd: each chunk costs about 1.5 kB).
    Styles that do not change (radii, draw order, fill) are logged once, static.
    """

    def __init__(
        self, rec, scene: SceneGeometry, series_every: int = 25, scene_every: int = 25
    ) -> None:
        self.rr = _rr()
        self.rec = rec
        self.scene = scene
        self.frames = 0
        self.series_every = max(int(series_every), 1)
        self.scene_every = max(int(scene_every), 1)
        self._series_ids: set[int] = set()
        self._series: dict[str, tuple[list[float], list[float]]] = {}
        self.margins: dict[int, float] = {}  # parcel id -> damage margin, once known
        self._damage_styled: set[str] = set()
        # parcel id -> (colour, label, w_n / w_dop, a_N / a_Ndop)
        self._risk_marks: dict[int, tuple] = {}
        self.last_seen: dict[int, tuple[float, float, float]] = {}  # id -> centre [m]
        self.outcomes: dict[int, tuple] = {}  # id -> (outcome, x, y, z), once known
        self._frames = _SceneColumns()
        self._log_static()

    def _scalar(self, entity: str, t: float, value: float) -> None:
        ts, vs = self._series.setdefault(entity, ([], []))
        ts.append(t)
        vs.append(value)

    def flush(self) -> None:
        """Send the buffered frames and time series."""
        self._flush_scene()
        rr = self.rr
        for entity, (ts, vs) in self._series.items():
            if ts:
                self.rec.send_columns(
                    entity,
                    indexes=[rr.TimeColumn(TIMELINE, duration=ts)],
                    columns=rr.Scalars.columns(scalars=vs),
                )
                ts.clear()
                vs.clear()

    def _flush_scene(self) -> None:
        rr, send, b = self.rr, self.rec.send_columns, self._frames
        if b.fence_t:
            index = [rr.TimeColumn(TIMELINE, duration=b.fence_t)]
            ones = [1] * len(b.fence_t)
            send("world/fence", index, rr.LineStrips3D.columns(strips=b.fence3d).partition(ones))
            send(f"{TOP}/fence", index, rr.LineStrips2D.columns(strips=b.fence2d).partition(ones))
        if b.t:
            index = [rr.TimeColumn(TIMELINE, duration=b.t)]
            n = b.parcels
            colors = np.array(b.colors, dtype=np.uint8).reshape(-1, 3)
            send(
                "world/parcels",
                index,
                rr.Boxes3D.columns(
                    centers=np.array(b.centers).reshape(-1, 3),
                    half_sizes=np.array(b.half_sizes).reshape(-1, 3),
                    quaternions=np.array(b.quats).reshape(-1, 4),
                    colors=colors,
                    labels=b.labels,
                ).partition(n),
            )
            strips = np.concatenate(b.footprints) if b.footprints else np.zeros((0, 5, 2))
            send(
                f"{TOP}/parcels",
                index,
                rr.LineStrips2D.columns(strips=strips, colors=colors, labels=b.labels).partition(
                    n
                ),
            )
            # the ids as dark labels of their own (a label takes its entity's colour: the
            # parcels' orange, grey or green under pale text is unreadable)
            centers = np.array(b.centers).reshape(-1, 3)
            tops = centers + np.array(b.half_sizes).reshape(-1, 3) * (0.0, 0.0, 1.0)
            send(
                "world/parcel_labels",
                index,
                rr.Points3D.columns(positions=tops, labels=b.labels).partition(n),
            )
            send(
                f"{TOP}/parcel_labels",
                index,
                rr.Points2D.columns(
                    positions=centers[:, :2] * (1.0, -1.0) - (0.0, LABEL_DROP), labels=b.labels
                ).partition(n),
            )
            origins = np.array(b.origins).reshape(-1, 3)
            vectors = np.array(b.vectors).reshape(-1, 3)
            send(
                "world/contact_forces",
                index,
                rr.Arrows3D.columns(origins=origins, vectors=vectors).partition(b.arrows),
            )
            flip = np.array([1.0, -1.0])
            send(
                f"{TOP}/contact_forces",
                index,
                rr.Arrows2D.columns(
                    origins=origins[:, :2] * flip, vectors=vectors[:, :2] * flip
                ).partition(b.arrows),
            )
        self._frames = _SceneColumns()

    def _log_static(self) -> None:
        rr, rec, sc = self.rr, self.rec, self.scene
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        x0, x1 = sc.belt_x
        s = sc.belt_width
        rec.log(
            "world/conveyor/belt",
            rr.Boxes3D(
                centers=[(0.5 * (x0 + x1), 0.5 * s, -0.01)],
                sizes=[(x1 - x0, s, 0.02)],
                colors=[(70, 70, 70)],
                fill_mode="solid",
            ),
            static=True,
        )
        rec.log(
            "world/conveyor/borders",
            rr.LineStrips3D([[(x0, 0.0, 0.0), (x1, 0.0, 0.0)], [(x0, s, 0.0), (x1, s, 0.0)]],
                            colors=[(220, 220, 60)], radii=0.005),
            static=True,
        )  # fmt: skip
        if sc.chute is not None:
            cx, cy, sx, sy = sc.chute
            rec.log(
                "world/chute",
                rr.Boxes3D(centers=[(cx, cy, -0.05)], sizes=[(sx, sy, 0.02)],
                           colors=[(50, 100, 200, 150)], fill_mode="solid"),
                static=True,
            )  # fmt: skip
            # its label dark (a label takes its entity's colour: the chute's translucent blue
            # reads pale), at the chute's far edge, off the belt and the parcels
            rec.log(
                "world/chute_label",
                rr.Points3D([(cx, cy + 0.5 * sy, 0.0)], colors=[LABEL_COLOR], radii=0.0,
                            labels=["chute"]),
                static=True,
            )  # fmt: skip
        if sc.scan_line_x is not None:
            x = sc.scan_line_x
            rec.log(
                "world/scan_line",
                rr.LineStrips3D([[(x, 0.0, 0.01), (x, s, 0.01)]], colors=[(255, 60, 60)],
                                radii=0.006, labels=["scan line"]),
                static=True,
            )  # fmt: skip
        self._log_static_top()
        self._log_static_styles()
        rec.log(
            "plots/fence/tip_deflection",
            rr.SeriesLines(names="tip yield -w, sampled [cm]", colors=[SAMPLED_COLOR]),
            static=True,
        )
        rec.log(
            "plots/fence/alpha_w",
            rr.SeriesLines(names="alpha_w [rad]", colors=[ALPHA_COLOR]),
            static=True,
        )

    def _log_static_top(self) -> None:
        """The static scene of the top view (view coordinates (x, -y), drawn under the rest)."""
        rr, rec, sc = self.rr, self.rec, self.scene
        x0, x1 = sc.belt_x
        s = sc.belt_width
        rec.log(
            f"{TOP}/conveyor/belt",
            rr.Boxes2D(centers=[(0.5 * (x0 + x1), -0.5 * s)], sizes=[(x1 - x0, s)],
                       colors=[(70, 70, 70)], draw_order=0.0),
            static=True,
        )  # fmt: skip
        rec.log(
            f"{TOP}/conveyor/borders",
            rr.LineStrips2D([[(x0, 0.0), (x1, 0.0)], [(x0, -s), (x1, -s)]],
                            colors=[(220, 220, 60)], radii=0.01, draw_order=1.0),
            static=True,
        )  # fmt: skip
        if sc.chute is not None:
            cx, cy, sx, sy = sc.chute
            rec.log(
                f"{TOP}/chute",
                rr.Boxes2D(centers=[(cx, -cy)], sizes=[(sx, sy)], colors=[(50, 100, 200)],
                           draw_order=0.5),
                static=True,
            )  # fmt: skip
            rec.log(
                f"{TOP}/chute/label",
                rr.Points2D([(cx, -cy - LABEL_DROP)], labels=["chute"], colors=[LABEL_COLOR],
                            radii=0.0, draw_order=2.0),
                static=True,
            )  # fmt: skip
        if sc.scan_line_x is not None:
            x = sc.scan_line_x
            rec.log(
                f"{TOP}/scan_line",
                rr.LineStrips2D([[(x, 0.0), (x, -s)]], colors=[(255, 60, 60)], radii=0.01,
                                draw_order=2.0),
                static=True,
            )  # fmt: skip
            # its name above the belt, clear of the parcels' ids where they enter
            rec.log(
                f"{TOP}/scan_line/label",
                rr.Points2D([(x, -s - 0.12 - LABEL_DROP)], labels=["scan line"],
                            colors=[LABEL_COLOR], radii=0.0, draw_order=2.0),
                static=True,
            )  # fmt: skip
        log_keys(rr, rec, sc, TOP)

    def _log_static_styles(self) -> None:
        """What does not change from frame to frame of the moving entities (static: it holds
        for every frame sent as columns)."""
        rr, rec = self.rr, self.rec
        fence_color = [(230, 80, 30)]
        force_color = [(255, 0, 255)]
        styles = {
            "world/fence": rr.LineStrips3D.from_fields(colors=fence_color, radii=0.01),
            "world/parcels": rr.Boxes3D.from_fields(fill_mode="solid", show_labels=False),
            "world/parcel_labels": rr.Points3D.from_fields(
                colors=[LABEL_COLOR], radii=0.0, show_labels=True
            ),
            f"{TOP}/parcel_labels": rr.Points2D.from_fields(
                colors=[LABEL_COLOR], radii=0.0, show_labels=True, draw_order=7.0
            ),
            "world/contact_forces": rr.Arrows3D.from_fields(colors=force_color, radii=0.008),
            f"{TOP}/fence": rr.LineStrips2D.from_fields(
                colors=fence_color, radii=0.015, draw_order=4.0
            ),
            f"{TOP}/parcels": rr.LineStrips2D.from_fields(
                radii=0.012, show_labels=False, draw_order=3.0
            ),
            f"{TOP}/contact_forces": rr.Arrows2D.from_fields(
                colors=force_color, radii=0.012, draw_order=5.0
            ),
        }
        for entity, style in styles.items():
            rec.log(entity, style, static=True)

    def log_frame(self, t: float, fence: FenceFrame | None, parcels: list[ParcelFrame]) -> None:
        """Everything that moves, at sim time ``t`` [s] (buffered, see the class doc)."""
        rr, rec, b = self.rr, self.rec, self._frames
        t = float(t)
        if fence is not None:
            node_x, node_y = np.asarray(fence.node_x), np.asarray(fence.node_y)
            b.fence_t.append(t)
            b.fence3d.append(np.column_stack((node_x, node_y, np.full(node_x.size, FENCE_Z))))
            b.fence2d.append(np.column_stack((node_x, -node_y)))
            self._scalar(
                "plots/fence/tip_deflection", t, float(fence.tip_deflection) / DEFLECTION_PLOT_UNIT
            )
            self._scalar("plots/fence/alpha_w", t, float(fence.alpha))
        b.t.append(t)
        b.parcels.append(len(parcels))
        arrows = 0
        for p in parcels:
            b.centers.append((p.center_x, p.center_y, 0.5 * p.height))
            b.half_sizes.append((0.5 * p.length_a, 0.5 * p.width_b, 0.5 * p.height))
            b.quats.append((0.0, 0.0, math.sin(0.5 * p.yaw), math.cos(0.5 * p.yaw)))
            b.labels.append(str(p.parcel_id))
            b.colors.append(self._color(p))
            self.last_seen[p.parcel_id] = (p.center_x, p.center_y, p.height)
            if p.n > 0.0 and math.isfinite(p.contact_x) and fence is not None:
                normal = _fence_normal(fence, p.contact_x, p.contact_y, p.center_x, p.center_y)
                b.origins.append((p.contact_x, p.contact_y, FENCE_Z))
                b.vectors.append(
                    (normal[0] * p.n * FORCE_SCALE, normal[1] * p.n * FORCE_SCALE, 0.0)
                )
                arrows += 1
            pid = p.parcel_id
            if pid not in self._series_ids:
                self._series_ids.add(pid)
                rec.log(
                    f"plots/contact/{pid}/N",
                    rr.SeriesLines(names=f"N {pid}", colors=[N_COLOR]),
                    static=True,
                )
                rec.log(
                    f"plots/contact/{pid}/N_stiff",
                    rr.SeriesLines(names=f"N_stiff {pid}", colors=[N_STIFF_COLOR]),
                    static=True,
                )
                rec.log(
                    f"plots/speed/{pid}",
                    rr.SeriesLines(
                        names=f"parcel {pid}", colors=[DIVERT_COLOR if p.divert else PASS_COLOR]
                    ),
                    static=True,
                )
            if 1 <= p.stage <= 4:  # forces only while the fence works on it (E1 .. E4)
                self._scalar(f"plots/contact/{pid}/N", t, float(p.n) / FORCE_PLOT_UNIT)
                self._scalar(f"plots/contact/{pid}/N_stiff", t, float(p.n_stiff) / FORCE_PLOT_UNIT)
            self._scalar(f"plots/speed/{pid}", t, math.hypot(p.vx, p.vy))
        if parcels:
            b.footprints.append(_footprints(parcels))
        b.arrows.append(arrows)
        self.frames += 1
        if self.frames % self.series_every == 0:
            self.flush()
        elif self.frames % self.scene_every == 0:
            self._flush_scene()

    def _color(self, p: ParcelFrame) -> tuple[int, int, int]:
        """What the scan decided: to divert or to pass (the outcome scheme; a damage margin
        shows on the parcel's damage mark)."""
        return DIVERT_COLOR if p.divert else PASS_COLOR

    def log_outcome(self, t: float, parcel_id: int, outcome: str) -> None:
        """A parcel's outcome (sorted, passed, missed, failed) at sim time ``t`` [s]: its mark
        where it was last seen (the outcome marks of every parcel so far are logged anew)."""
        at = self.last_seen.get(parcel_id)
        if at is None:
            return
        self._flush_scene()  # the parcel's last frames before its mark
        self.outcomes[parcel_id] = (outcome, *at)
        self.rec.set_time(TIMELINE, duration=float(t))
        log_outcome_marks(self.rr, self.rec, TOP, self.outcomes)

    def log_event(self, ev, risk: dict | None = None) -> None:
        """One sorting event at the solver's resolution
        (:class:`fence_sorter.analysis.events.SortEventData`): N at every step and the
        N_stiff course (``plots/contact/<id>/N_steps``, ``.../N_stiff_course``), the tip
        deflection at every step (``plots/fence/tip_deflection/steps/<id>``); with ``risk``
        (:func:`fence_sorter.analysis.events.risk_of` of its outcome) the damage-risk points
        at the outcome time and the parcel's colour in the views."""
        rr, rec, pid = self.rr, self.rec, ev.parcel_id
        series = (
            (f"plots/contact/{pid}/N_steps", f"N {pid} (solver steps) [kN]", N_COLOR, ev.t,
             np.asarray(ev.normal_force, dtype=float) / FORCE_PLOT_UNIT),
            (f"plots/contact/{pid}/N_stiff_course", f"N_stiff {pid} (stiff obstacle) [kN]",
             N_STIFF_COLOR, ev.stiff_t, np.asarray(ev.stiff_force, dtype=float) / FORCE_PLOT_UNIT),
            (f"plots/fence/tip_deflection/steps/{pid}", f"tip yield -w, stroke {pid} [cm]",
             STEPS_COLOR, ev.t, np.asarray(ev.tip_deflection, dtype=float) / DEFLECTION_PLOT_UNIT),
        )  # fmt: skip
        for entity, name, colour, t, values in series:
            rec.log(entity, rr.SeriesLines(names=name, colors=[colour]), static=True)
            if len(t):
                rec.send_columns(
                    entity,
                    indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=float))],
                    columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=float)),
                )
        if risk is None:
            return
        self.margins[pid] = min(risk["impact_speed_margin"], risk["accel_margin"])
        # a mark per parcel in its margin's colour, labelled with its id and margins, in a
        # grid under the belt (where the parcels leave the belt, their marks would pile up)
        w_n = ev.impact_speed[0] if len(ev.impact_speed) else math.nan
        a_ratio = 1.0 - risk["accel_margin"]
        self._risk_marks[pid] = (
            margin_color(self.margins[pid]),
            f"{pid}: m_w {risk['impact_speed_margin']:+.2f}, m_a {risk['accel_margin']:+.2f}",
            w_n / risk["w_dop"] if risk["w_dop"] > 0 else math.nan,
            a_ratio,
        )
        rec.set_time(TIMELINE, duration=float(ev.t_outcome))
        self._log_risk_marks()
        peak_n = (1.0 - risk["accel_margin"]) * risk["a_ndop"] * ev.mass
        points = (
            ("damage/w_n/value", "w_n", w_n),
            ("damage/w_n/limit", "w_dop", risk["w_dop"]),
            ("damage/a_N/value", "a_N", a_ratio * risk["a_ndop"] / ACCEL_PLOT_UNIT),
            ("damage/a_N/limit", "a_Ndop", risk["a_ndop"] / ACCEL_PLOT_UNIT),
            ("damage/N/value", "peak N [kN]", peak_n / FORCE_PLOT_UNIT),
            ("damage/N/limit", "a_Ndop m_p [kN]", risk["a_ndop"] * ev.mass / FORCE_PLOT_UNIT),
        )
        rec.set_time(TIMELINE, duration=float(ev.t_outcome))
        for entity, name, value in points:
            if entity not in self._damage_styled:
                self._damage_styled.add(entity)
                style = rr.SeriesPoints(
                    names=name,
                    markers="cross" if entity.endswith("limit") else "circle",
                    colors=[MARGIN_COLORS[0] if entity.endswith("limit") else N_COLOR],
                    marker_sizes=4.0,
                )
                rec.log(entity, style, static=True)
            if math.isfinite(value):
                rec.log(entity, rr.Scalars(float(value)))

    def _log_risk_marks(self) -> None:
        """The top view's damage marks and the damage-risk chart, every parcel so far (in
        the order of their outcomes)."""
        rr, rec = self.rr, self.rec
        marks = list(self._risk_marks.items())
        at = np.array([risk_mark_position(self.scene, k) for k in range(len(marks))])
        rec.log(
            f"{TOP}/damage_risk",
            rr.Points2D(at, colors=[m[0] for _, m in marks], radii=0.04, draw_order=6.0),
        )  # fmt: skip
        # the labels dark, beside their marks (a label is centred on its point)
        step = (self.scene.belt_x[1] - self.scene.belt_x[0]) / RISK_MARKS_PER_ROW
        rec.log(
            f"{TOP}/damage_risk_labels",
            rr.Points2D(at + (0.5 * step, 0.0), colors=[LABEL_COLOR], radii=0.001,
                        labels=[m[1] for _, m in marks], draw_order=6.0),
        )  # fmt: skip
        # the chart: per parcel a column at x = k (k-th outcome), w_n / w_dop (circle, left)
        # and a_N / a_Ndop (square, right) upwards, the limit at 1; view y points down
        cols = np.arange(len(marks), dtype=float)
        w = np.array([m[2] for _, m in marks], dtype=float)
        a = np.array([m[3] for _, m in marks], dtype=float)
        ok = np.isfinite(w)
        rec.log(
            f"{RISK}/w_n",
            rr.Points2D(np.column_stack((cols[ok] - 0.15, -w[ok])), radii=0.06,
                        colors=[N_COLOR]),
        )  # fmt: skip
        ok = np.isfinite(a)
        rec.log(
            f"{RISK}/a_N",
            rr.Points2D(np.column_stack((cols[ok] + 0.15, -a[ok])), radii=0.06,
                        colors=[N_STIFF_COLOR]),
        )  # fmt: skip
        rec.log(
            f"{RISK}/parcels",
            rr.Points2D(np.column_stack((cols, np.full(cols.size, 0.12))), radii=0.001,
                        colors=[LABEL_COLOR], labels=[f"parcel {pid}" for pid, _ in marks]),
        )  # fmt: skip
        # the limit (red), 0 (grey), 0.5 (pale) and a pale frame that keeps the labels in the
        # picture; the y scale: the ratios 0, 0.5 and 1 written left of the lines
        right = max(len(marks) - 0.4, 3.6)
        rec.log(
            f"{RISK}/scale",
            rr.LineStrips2D(
                [[(-0.6, -1.0), (right, -1.0)], [(-0.6, 0.0), (right, 0.0)],
                 [(-0.6, -0.5), (right, -0.5)],
                 [(-0.9, -1.3), (right, -1.3), (right, 0.3), (-0.9, 0.3), (-0.9, -1.3)]],
                colors=[MARGIN_COLORS[0], SAMPLED_COLOR, (225, 225, 225), (225, 225, 225)],
                radii=0.01,
            ),
        )  # fmt: skip
        rec.log(
            f"{RISK}/scale_labels",
            rr.Points2D([(-0.75, -v) for v in RISK_TICKS], colors=[LABEL_COLOR], radii=0.001,
                        labels=[f"{v:g}" for v in RISK_TICKS]),
        )  # fmt: skip

    def close(self) -> None:
        self.flush()
        self.rec.flush()
        self.rec.disconnect()


@dataclass
class _SceneColumns:
    """Frames buffered for :meth:`RerunLogger._flush_scene` (per frame: counts; per parcel
    and per arrow: values)."""

    t: list[float] = field(default_factory=list)
    fence_t: list[float] = field(default_factory=list)
    fence3d: list[np.ndarray] = field(default_factory=list)
    fence2d: list[np.ndarray] = field(default_factory=list)
    parcels: list[int] = field(default_factory=list)
    centers: list[tuple] = field(default_factory=list)
    half_sizes: list[tuple] = field(default_factory=list)
    quats: list[tuple] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    colors: list[tuple] = field(default_factory=list)
    footprints: list[np.ndarray] = field(default_factory=list)
    arrows: list[int] = field(default_factory=list)
    origins: list[tuple] = field(default_factory=list)
    vectors: list[tuple] = field(default_factory=list)


_CORNERS = np.array([(0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5), (0.5, -0.5), (0.5, 0.5)])


def _footprints(parcels: list[ParcelFrame]) -> np.ndarray:
    """Closed outlines of the parcels' rotated footprints in top-view coordinates (x, -y),
    shape (parcels, 5, 2)."""
    if not parcels:
        return np.zeros((0, 5, 2))
    p = np.array([(q.center_x, q.center_y, q.length_a, q.width_b, q.yaw) for q in parcels])
    c, s = np.cos(p[:, 4])[:, None], np.sin(p[:, 4])[:, None]
    u = _CORNERS[None, :, 0] * p[:, 2, None]  # along the parcel's length a
    v = _CORNERS[None, :, 1] * p[:, 3, None]  # along its width b
    x = p[:, 0, None] + c * u - s * v
    y = p[:, 1, None] + s * u + c * v
    return np.stack((x, -y), axis=-1)


def _fence_normal(fence: FenceFrame, x: float, y: float, cx: float, cy: float):
    """Unit normal of the fence segment nearest (x, y), pointing towards the parcel centre."""
    nx, ny = np.asarray(fence.node_x), np.asarray(fence.node_y)
    if nx.size < 2:
        return (0.0, 1.0)
    k = int(np.argmin((nx - x) ** 2 + (ny - y) ** 2))
    k = min(max(k, 0), nx.size - 2)
    dx, dy = nx[k + 1] - nx[k], ny[k + 1] - ny[k]
    norm = math.hypot(dx, dy) or 1.0
    n = (-dy / norm, dx / norm)
    if (cx - x) * n[0] + (cy - y) * n[1] < 0:
        n = (-n[0], -n[1])
    return n


#: the logger and, for its callers, the frames and layout it draws with
__all__ = [
    "ALPHA_AXIS",
    "ALPHA_COLOR",
    "APP_ID",
    "CONTACT_AXIS",
    "DEFLECTION_AXIS",
    "DEFLECTION_PLOT_UNIT",
    "DIVERT_COLOR",
    "FENCE_Z",
    "FORCE_PLOT_UNIT",
    "FORCE_SCALE",
    "FenceFrame",
    "LABEL_COLOR",
    "MARGIN_COLORS",
    "MARGIN_RANGE",
    "N_COLOR",
    "N_STIFF_COLOR",
    "PASS_COLOR",
    "ParcelFrame",
    "RISK",
    "RISK_MARKS_PER_ROW",
    "RISK_ROW",
    "RISK_ROWS_FRAMED",
    "RISK_TICKS",
    "RerunLogger",
    "SAMPLED_COLOR",
    "OUTCOME_COLORS",
    "PARCEL_COLORS",
    "SPEED_AXIS",
    "SPEED_AXIS_MAX",
    "STEPS_COLOR",
    "SceneGeometry",
    "TIMELINE",
    "TOP",
    "bag_frames",
    "blueprint",
    "camera_position",
    "camera_target",
    "frames_from_snapshot",
    "margin_color",
    "open_recording",
    "risk_mark_position",
    "scene_from_bag",
    "top_view_bounds",
]
