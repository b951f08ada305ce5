"""The live Rerun view of a line over DDS (``fence-sorter run --line L --rerun-url URL`` or
``--live-rrd FILE``), a process of its own on the owner's host (namespace ``/line``).

It subscribes to every unit's view (``/<unit>/load_states`` and ``/<unit>/fence_state``,
which ``line_unit`` publishes every ``view_period`` of sim time: the parcels in the unit's
simulation, then its fence) and to the hand-off links (``/line/handoffs`` and every
``/<unit>/handoffs``: each parcel's sizes, C_s offsets and destination as the unit that
took it has them), and logs the line view of :mod:`fence_sorter.visualisation.line_view`
with the same entity paths, layout and look: the same
:meth:`~fence_sorter.visualisation.line_view.LineRerunLogger.add` takes the fences and the
parcels in the line frame, from the units' messages here and from a ``LinePlant`` in
``line-sim --rrd``.

A sample at sim time t is logged once every unit's fence of t has come, or, for a unit whose
sample was lost (best effort), once a later one of that unit has (its previous fence is drawn
again). Parcels are those of the units' simulations (a unit's zone runs from 2 m before its
fence axis to 3 m after it: a parcel between two zones, before the first or after the last is
not drawn), the one of the unit furthest down the belt when two units hold a parcel; a
parcel sorted leaves the view. Coloured by the destination its hand-off carries; a parcel
whose destination no scan has read yet is grey, labelled ``?``.

The node ends by itself: once the owner's summary is on ``/line/summary`` and no view message
came for ``drain_time``, it closes the recording and exits 0 (on SIGINT/SIGTERM as well).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from dataclasses import replace

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from fence_sorter.line.line_file import load_line
from fence_sorter.line.routing import to_local
from fence_sorter.line.unit import ID_STRIDE, local_offsets
from fence_sorter.nodes.base import FenceSorterNode, run_node
from fence_sorter.nodes.convert import handoff_from_msg
from fence_sorter.nodes.line_unit import (
    INDUCTION_TOPIC,
    LINE_QOS,
    VIEW_FENCE,
    VIEW_LOADS,
    handoff_topic,
)
from fence_sorter.nodes.parameters import LINE_VIEWER_PARAMETERS
from fence_sorter.nodes.qos import profile
from fence_sorter.recording.topics import LINE_SUMMARY, LINE_SUMMARY_QOS
from fence_sorter.visualisation.line_view import (
    LineRerunLogger,
    fence_strip,
    line_blueprint,
    open_recording,
    parcel_frame,
    parcel_label,
)
from fence_sorter_msgs.msg import FenceState, LoadState
from fence_sorter_msgs.msg import HandOff as HandOffMsg

#: the view's subscriptions: best effort (as published), a deep history so that a busy
#: executor does not lose a sample's parcels
VIEW_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT
)
#: LoadState.STAGE_SORTED: a sorted parcel leaves the view
STAGE_SORTED = 5
#: a parcel whose destination no scan has read yet
UNREAD_COLOR = (150, 150, 150)
UNREAD = "?"


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _yaw(q) -> float:
    return 2.0 * math.atan2(q.z, q.w)


class LineViewerNode(FenceSorterNode):
    NODE_NAME = "line_viewer"
    STATUS = "viewing the line"
    PARAMETERS = LINE_VIEWER_PARAMETERS
    PINNED_CLOCK = False

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        p = self.parameter_values()
        self.line = load_line(p["line"])
        rrd, url = str(p["rrd"]), str(p["url"])
        if not rrd and not url:
            raise ValueError("rrd, url: give an .rrd file, a viewer's URL or both")
        rec = open_recording(
            rrd or None, url=url or None, layout=lambda paused: line_blueprint(self.line, paused)
        )
        self.logger = LineRerunLogger(rec, self.line, flush_every=int(p["flush_every"]))
        self.drain_time = float(p["drain_time"])
        n = len(self.line.units)
        # (line id, pass, unit) -> (spec as the unit's simulation has it, destination read)
        self.specs: dict[tuple[int, int, int], object] = {}
        self.destination: dict[int, str] = {}  # line id -> the destination a scan read
        self.loads: list[dict[int, list[LoadState]]] = [{} for _ in range(n)]
        self.fences: dict[int, dict[int, tuple[FenceState, list[LoadState]]]] = {}
        self.latest = [-1] * n  # each unit's latest fence stamp [ns]
        self.shown: list[FenceState | None] = [None] * n  # each unit's fence last drawn
        self.unknown = 0  # parcels of a sample without their hand-off (not drawn)
        self.closed = False
        self.summary_seen = False
        self.last_message = time.monotonic()
        for k, u in enumerate(self.line.units):
            self.create_subscription(
                LoadState, f"/{u.name}/{VIEW_LOADS}", lambda m, k=k: self._on_load(k, m),
                VIEW_QOS,
            )  # fmt: skip
            self.create_subscription(
                FenceState, f"/{u.name}/{VIEW_FENCE}", lambda m, k=k: self._on_fence(k, m),
                VIEW_QOS,
            )  # fmt: skip
        for topic in [INDUCTION_TOPIC, *(handoff_topic(u.name) for u in self.line.units)]:
            self.create_subscription(HandOffMsg, topic, self._on_handoff, LINE_QOS)
        self.create_subscription(String, LINE_SUMMARY, self._on_summary, profile(LINE_SUMMARY_QOS))
        self._end_timer = self.create_timer(0.1, self._check_end)

    # -- callbacks ------------------------------------------------------------------------
    def _on_handoff(self, msg: HandOffMsg) -> None:
        h = handoff_from_msg(msg)
        if h.destination:
            self.destination[h.parcel_id] = h.destination
        k = h.to_unit
        if not 0 <= k < len(self.line.units):  # to the recirculation
            return
        us = self.line.units[k]
        _, _, yaw = to_local(us.position, us.mirrored, self.line.width, h.x, h.y, h.yaw)
        _, cx, cy = local_offsets(us.mirrored, yaw, h.spec.cog_offset_x, h.spec.cog_offset_y)
        self.specs[(h.parcel_id, h.passes, k)] = replace(h.spec, cog_offset_x=cx, cog_offset_y=cy)

    def _on_load(self, k: int, msg: LoadState) -> None:
        self.last_message = time.monotonic()
        self.loads[k].setdefault(_ns(msg.header.stamp), []).append(msg)

    def _on_fence(self, k: int, msg: FenceState) -> None:
        self.last_message = time.monotonic()
        stamp = _ns(msg.header.stamp)
        # the unit's parcels of this sample came before its fence; older ones' are lost
        loads = self.loads[k].pop(stamp, [])
        for s in [s for s in self.loads[k] if s < stamp]:
            del self.loads[k][s]
        self.fences.setdefault(stamp, {})[k] = (msg, loads)
        self.latest[k] = max(self.latest[k], stamp)
        self._emit()

    def _on_summary(self, _msg: String) -> None:
        self.summary_seen = True

    # -- samples --------------------------------------------------------------------------
    def _emit(self) -> None:
        """Log every sample that is complete, or whose missing units have gone past it."""
        n = len(self.line.units)
        while self.fences:
            stamp = min(self.fences)
            got = self.fences[stamp]
            if len(got) < n and any(self.latest[k] <= stamp for k in range(n) if k not in got):
                return
            del self.fences[stamp]
            self._sample(stamp * 1e-9, got)

    def _sample(self, t: float, got: dict[int, tuple[FenceState, list[LoadState]]]) -> None:
        width = self.line.width
        fences, alphas, forces = [], [], []
        frames: dict[int, tuple] = {}  # line id -> (frame, label, colour); the last unit's
        for k, us in enumerate(self.line.units):
            fence, loads = got.get(k, (self.shown[k], []))
            if fence is None:
                return  # no fence of this unit yet: nothing to draw it with
            self.shown[k] = fence
            fences.append(fence_strip(us, width, fence.node_x, fence.node_y))
            alphas.append(fence.drive_angle)
            forces.append(max((q.contact_normal_force for q in loads), default=0.0))
            for q in loads:
                if q.stage == STAGE_SORTED:
                    continue
                pid, passes = divmod(int(q.parcel_id), ID_STRIDE)
                spec = self.specs.get((pid, passes, k))
                if spec is None:
                    self.unknown += 1
                    continue
                pos = q.pose.position
                fr = parcel_frame(us, width, pid, spec, pos.x, pos.y, _yaw(q.pose.orientation))
                dest = self.destination.get(pid, "")
                colour = self.logger.dest_color.get(dest, UNREAD_COLOR)
                frames[pid] = (fr, parcel_label(pid, dest or UNREAD), colour)
        rows = [frames[pid] for pid in sorted(frames)]
        self.logger.add(
            t, fences, alphas, forces, [r[0] for r in rows], [r[1] for r in rows],
            [r[2] for r in rows],
        )  # fmt: skip

    # -- the end --------------------------------------------------------------------------
    def _check_end(self) -> None:
        if self.summary_seen and time.monotonic() - self.last_message > self.drain_time:
            self.close()
            rclpy.try_shutdown()

    def close(self) -> None:
        """Log what is complete, send what is buffered and close the sinks (once)."""
        if self.closed:
            return
        self.closed = True
        for stamp in sorted(self.fences):  # what the last units' samples left
            self._sample(stamp * 1e-9, self.fences.pop(stamp))
        self.logger.close()
        self.get_logger().info(f"line view: {self.logger.samples} samples logged")

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        values = {"samples": self.logger.samples, "parcels_unknown": self.unknown}
        status.values.extend(KeyValue(key=k, value=str(v)) for k, v in values.items())
        return status


class _Viewer(LineViewerNode):
    """The viewer :func:`main` ran (kept to close its recording)."""

    last: LineViewerNode | None = None

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        _Viewer.last = self


def main(args: Sequence[str] | None = None) -> int:
    """Log the line's live view until the line is over (or Ctrl-C, SIGTERM); exit 2 with one
    line on a bad line file or parameter."""
    try:
        code = run_node(_Viewer, args)
    except ValueError as exc:
        print(f"line_viewer: {exc}", file=sys.stderr)
        return 2
    if _Viewer.last is not None:
        _Viewer.last.close()
    return code


if __name__ == "__main__":
    raise SystemExit(main())
