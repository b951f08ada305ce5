"""The Rerun recording and its default layout (blueprint): where the top view is framed, where
the 3D eye stands, which plots sit where, and the recording stream that saves to an ``.rrd``
and/or streams to a viewer. Entity roots: ``world`` (3D), ``top`` (2D top view, view
coordinates ``(x, -y)``), ``risk`` (the damage-risk chart), ``plots/...``, ``damage/...``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from fence_sorter.visualisation.frames import SceneGeometry
from fence_sorter.visualisation.rerun_keys import legend_height

APP_ID = "fence_sorter"
TIMELINE = "sim_time"
TOP = "top"  # root of the 2D top-view entities
#: the speed plot's axis runs to this (the parcels' speeds stay below) [m/s]
SPEED_AXIS_MAX = 3.0
#: the plots show forces in kN and the fence tip's yield -w in cm (value / unit): with the
#: fixed y ranges below every time series plot's tick labels are single digits (the ticks are
#: at whole numbers), so the plot areas start at one x (the viewer sizes a y axis to its
#: widest label) and one instant is at one x position on every plot; each range reaches a
#: little below 0, so the label 0 clears the time axis's labels
FORCE_PLOT_UNIT = 1000.0  # [N]
DEFLECTION_PLOT_UNIT = -0.01  # [m]: -w in cm, positive where the tip yields under load
CONTACT_AXIS = (-0.25, 3.0)  # [kN]
DEFLECTION_AXIS = (-0.5, 2.5)  # [cm]
ALPHA_AXIS = (-0.2, 2.0)  # [rad]
SPEED_AXIS = (-0.25, SPEED_AXIS_MAX)  # [m/s]
#: the damage-risk tab's plots: impact speed [m/s], peak acceleration [10^2 m/s^2] and peak
#: force [kN], each with single-digit tick labels like the time series (the paper's limits
#: w_dop 2.4 m/s and a_Ndop 300 m/s^2 of a 7 kg parcel, 2.1 kN, inside with headroom)
ACCEL_PLOT_UNIT = 100.0  # [m/s^2]
DAMAGE_SPEED_AXIS = (-0.25, SPEED_AXIS_MAX)  # [m/s]
DAMAGE_ACCEL_AXIS = (-0.25, 4.0)  # [10^2 m/s^2]
DAMAGE_FORCE_AXIS = (-0.25, 4.0)  # [kN]
TOP_VIEW_NAME = "top view [m], belt running to the right"
RISK = "risk"  # root of the damage-risk chart (one column per parcel, value / limit upwards)
#: the top view's damage marks: a grid below the belt, this many per row, rows this far apart
RISK_MARKS_PER_ROW = 4
RISK_ROW = 0.16  # [m]
RISK_ROWS_FRAMED = 4  # rows the top view's bounds leave room for
TIME_END_MARGIN = 0.03  # the plots' time axis runs this share past the recording's end


def _rr():
    os.environ.setdefault("RERUN_ANALYTICS_ENABLED", "false")  # no outside network here
    import rerun as rr  # lazy: Rerun (0.5 s), only to log

    return rr


def top_view_bounds(
    scene: SceneGeometry, margin: float = 0.3, legend: bool = False
) -> tuple[tuple, tuple]:
    """(x range, y range) of the top view [m, view coordinates]: belt, chute and scan line
    (and with ``legend`` the legend above them)."""
    x0, x1 = scene.belt_x
    y_max = scene.belt_width
    if scene.chute is not None:
        cx, cy, sx, sy = scene.chute
        x0, x1 = min(x0, cx - 0.5 * sx), max(x1, cx + 0.5 * sx)
        y_max = max(y_max, cy + 0.5 * sy)
    if scene.scan_line_x is not None:
        x0, x1 = min(x0, scene.scan_line_x), max(x1, scene.scan_line_x)
    below = RISK_ROW * (RISK_ROWS_FRAMED + 1)  # the damage marks' grid under the belt
    if legend:
        y_max += legend_height()
    return (x0 - margin, x1 + margin), (-y_max - margin, below + margin)


def risk_mark_position(scene: SceneGeometry, k: int) -> tuple[float, float]:
    """Top-view position (view coordinates) of the k-th damage mark (k = 0, 1, ...): a grid
    under the belt (the side away from the chute), RISK_MARKS_PER_ROW marks a row, so the
    labels never pile up where the parcels leave the belt."""
    x0, x1 = scene.belt_x
    col, row = k % RISK_MARKS_PER_ROW, k // RISK_MARKS_PER_ROW
    step = (x1 - x0) / RISK_MARKS_PER_ROW
    return (x0 + 0.05 * step + col * step, RISK_ROW * (row + 1))


def camera_target(scene: SceneGeometry) -> tuple[float, float, float]:
    """Centre of belt, chute and scan line in the frame sorter [m]: where the 3D eye looks."""
    (x0, x1), (vy0, vy1) = top_view_bounds(scene, margin=0.0)
    return (0.5 * (x0 + x1), -0.5 * (vy0 + min(vy1, 0.0)), 0.0)


def camera_position(scene: SceneGeometry) -> tuple[float, float, float]:
    """The 3D eye: from the fence side (y < 0) and above, far enough that the whole belt
    (scan line to end) and the chute are in the picture [m]."""
    (x0, x1), _ = top_view_bounds(scene, margin=0.0)
    cx, cy, _ = camera_target(scene)
    reach = 1.2 * (x1 - x0)  # about 1.15 reach away: the belt spans 3/4 of a 60 degree view
    return (cx, cy - 0.6 * reach, 0.75 * reach)


def time_plot(
    name: str,
    origin: str,
    y_range: tuple[float, float] | None = None,
    t_end: float | None = None,
):
    """A time series view showing the whole timeline (the same time range in every plot,
    not each its own data's), a fixed y range and no legend (its title names the colours).
    ``t_end``: the recording's last instant [s]; the plots run :data:`TIME_END_MARGIN` of it
    further, so the time cursor at the end is drawn whole."""
    import rerun.blueprint as rrb  # lazy: Rerun (0.5 s), only to log

    end = (
        rrb.TimeRangeBoundary.absolute(seconds=(1.0 + TIME_END_MARGIN) * t_end)
        if t_end is not None and math.isfinite(t_end)
        else rrb.TimeRangeBoundary.infinite()
    )
    whole = rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(), end=end)
    return rrb.TimeSeriesView(
        name=name,
        origin=origin,
        axis_x=rrb.TimeAxis(link="Independent", view_range=whole),
        axis_y=rrb.ScalarAxis(range=y_range) if y_range else None,
        plot_legend=rrb.PlotLegend(visible=False),
    )


def blueprint(
    scene: SceneGeometry | None = None, paused: bool = False, t_end: float | None = None
):
    """Default layout: the top view (2D, framed on the belt and chute when ``scene`` is given)
    on the left with the 3D scene in a tab behind it; on the right the time series (forces,
    tip deflection, alpha_w, speeds) with the damage-risk plots in a tab behind them.

    Every plot shows the whole timeline (the same time range in all of them, not each its own
    data's) and the time series a fixed y range whose tick labels are single digits: the
    viewer sizes a y axis to its widest tick label, so their plot areas start at one x and one
    instant is at one x position on every time series plot. No plot has a legend: each
    title says what its colours mean (a legend of per-parcel series covers the data).
    ``paused``: a recording that is complete opens paused (a live one follows its data);
    ``t_end``: its last instant [s] (see :func:`time_plot`)."""
    import rerun.blueprint as rrb  # lazy: Rerun (0.5 s), only to log

    bounds = None
    if scene is not None:
        x_range, y_range = top_view_bounds(scene, legend=True)
        bounds = rrb.VisualBounds2D(x_range=x_range, y_range=y_range)

    def plot(name, origin, y_range):
        return time_plot(name, origin, y_range, t_end)

    layout = rrb.Horizontal(
        rrb.Tabs(
            rrb.Spatial2DView(name=TOP_VIEW_NAME, origin=TOP, visual_bounds=bounds),
            rrb.Spatial3DView(
                name="sorter 3D",
                origin="world",
                eye_controls=rrb.EyeControls3D(
                    position=camera_position(scene), look_target=camera_target(scene)
                )
                if scene is not None
                else None,
            ),
            active_tab=0,
        ),
        rrb.Tabs(
            rrb.Vertical(
                plot("contact force [kN]: N blue, N_stiff orange", "plots/contact", CONTACT_AXIS),
                plot(
                    "fence tip yield -w [cm]: solver steps blue, sampled grey",
                    "plots/fence/tip_deflection",
                    DEFLECTION_AXIS,
                ),
                plot("drive angle alpha_w [rad]", "plots/fence/alpha_w", ALPHA_AXIS),
                plot(
                    "parcel speed [m/s]: to divert blue, to pass grey",
                    "plots/speed",
                    SPEED_AXIS,
                ),
                name="time series",
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    name="per parcel, value / limit: w_n blue, a_N orange, limit red",
                    origin=RISK,
                ),
                plot(
                    "impact speed w_n [m/s]: o parcels, x w_dop",
                    "damage/w_n",
                    DAMAGE_SPEED_AXIS,
                ),
                plot(
                    "peak acceleration a_N [10^2 m/s^2]: o parcels, x a_Ndop",
                    "damage/a_N",
                    DAMAGE_ACCEL_AXIS,
                ),
                plot(
                    "peak force N [kN]: o parcels, x a_Ndop m_p",
                    "damage/N",
                    DAMAGE_FORCE_AXIS,
                ),
                row_shares=[2, 1, 1, 1],
                name="damage risk",
            ),
            active_tab=0,
        ),
        column_shares=[3, 2],
    )
    parts = [layout]
    if paused:
        parts.append(rrb.TimePanel(timeline=TIMELINE, play_state="paused", state="collapsed"))
    return rrb.Blueprint(*parts, collapse_panels=True)


def open_recording(
    path: Path | str | None = None,
    spawn: bool = False,
    url: str | None = None,
    recording_id=None,
    scene: SceneGeometry | None = None,
    layout=None,
    t_end: float | None = None,
):
    """A RecordingStream saving to ``path`` (.rrd), and/or streaming to a viewer: a spawned one
    (``spawn``) or one listening at ``url`` (gRPC, e.g. rerun+http://127.0.0.1:9876/proxy),
    with ``layout`` (a function of ``paused`` giving a blueprint; default :func:`blueprint`,
    ``scene`` framing the top view, ``t_end`` the last instant) as the default layout;
    without ``url`` (no live viewer follows it) the recording opens paused."""
    rr = _rr()
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
    # one timeline, sim time: no log_time / log_tick beside it in the plots and time panel
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    if spawn:
        rec.spawn(connect=False)
    sinks = []
    if path is not None:
        sinks.append(rr.FileSink(str(path)))
    if spawn or url:
        sinks.append(rr.GrpcSink(url) if url else rr.GrpcSink())
    if sinks:
        paused = url is None
        default = (
            layout(paused) if layout is not None else blueprint(scene, paused=paused, t_end=t_end)
        )
        rec.set_sinks(*sinks, default_blueprint=default)
    return rec
