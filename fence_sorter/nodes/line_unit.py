"""One unit of a line over DDS: a :class:`~fence_sorter.line.lockstep.UnitSide` in its namespace.

Started in the namespace ``/<unit name>`` (``/unit_1``, ...); its own topic names are relative:

- ``commands`` (std_msgs/String, in): the line owner's numbered command stream, each message
  one or more :class:`~fence_sorter.line.lockstep.Command` in the wire format of
  :func:`~fence_sorter.line.lockstep.encode`, one a line (the owner sends the commands up to
  one the unit answers in one message), then ``end`` once the line is over (the unit exits
  0: a unit on another host ends with the line); an ``end`` before the owner's report (the
  last command of a line) is not the owner's: refused and counted (``ends_refused``);
- ``replies`` (std_msgs/String, out): ``ready<token>`` (a token of this process: the owner
  tells a new process of the unit from the one it ran with) until the first command comes,
  then the answers (Delivered, Done, Figures) in the same format;
- ``handoffs`` (fence_sorter_msgs/HandOff, out): the hand-offs to the downstream unit, or to
  the recirculation after the last unit;
- the upstream link (HandOff, in): ``/line/handoffs`` (the induction) for the first unit, else
  ``/<upstream unit name>/handoffs``;
- ``transit`` (std_msgs/String, out): once, at ``end``, the transit time of every hand-off
  that arrived on the upstream link (DDS source timestamp to reception, ns; JSON list);
- ``load_states`` (fence_sorter_msgs/LoadState, out) and ``fence_state`` (FenceState, out):
  with ``view_period`` > 0, the unit's view every ``view_period`` of sim time, after the step
  that reaches it: each parcel in its simulation, then its fence (the last message of a
  sample), in its frame ``<unit>/sorter``, stamped with the sim time; best effort, as the
  single-unit simulator publishes them (the line's live view, ``nodes/line_viewer.py``).

Every lockstep topic is reliable and keep-all (``commands``: the latest 1000 kept, more than a
unit is ever behind in lockstep): nothing is dropped silently. The heartbeat on
/diagnostics counts the hand-offs at this end of both links: arrived on the upstream one,
received (taken at the scan line), refused per reason and lost; published on the downstream one.

A unit whose owner falls silent (no command for ``owner_timeout`` once the line runs: the
owner's process or host is gone, or it took this unit for down) exits with
:data:`EXIT_OWNER_GONE` and one line saying so.
"""

from __future__ import annotations

import inspect
import json
import math
import sys
import time
import uuid
from collections.abc import Callable, Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from fence_sorter.line.handoff import HandOff
from fence_sorter.line.line_file import load_line
from fence_sorter.line.lockstep import (
    EXIT_OWNER_GONE,
    UnitSide,
    decode,
    encode,
    make_unit,
    split_batch,
)
from fence_sorter.line.multi_unit import LineRunConfig
from fence_sorter.nodes.base import FenceSorterNode, run_node
from fence_sorter.nodes.convert import (
    fill_fence_state,
    fill_load_state,
    handoff_from_msg,
    handoff_to_msg,
)
from fence_sorter.nodes.parameters import LINE_UNIT_PARAMETERS
from fence_sorter.nodes.qos import SENSOR_QOS
from fence_sorter_msgs.msg import FenceState, LoadState
from fence_sorter_msgs.msg import HandOff as HandOffMsg

#: the line's lockstep topics: reliable, keep-all (a writer blocks rather than drop)
LINE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL, depth=1, reliability=ReliabilityPolicy.RELIABLE
)
#: the owner's commands to a unit: reliable, the latest COMMAND_DEPTH kept. In lockstep a live
#: unit is never more than a step's commands behind (the owner waits for its replies every
#: step); a dead process's reader, still matched until its participant's lease runs out, must
#: not fill the writer's history (keep-all would then block the owner's publish)
COMMAND_DEPTH = 1000
COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=COMMAND_DEPTH, reliability=ReliabilityPolicy.RELIABLE
)
#: the induction's hand-offs to the first unit (the owner's namespace is /line)
INDUCTION_TOPIC = "/line/handoffs"
READY = "ready"
#: the owner's last message on ``commands``: the line is over, the unit exits 0
END = "end"
_MSG_AND_INFO = inspect.Signature(
    [inspect.Parameter(n, inspect.Parameter.POSITIONAL_ONLY) for n in ("msg", "info")]
)
#: a unit's hand-offs' transit times [ns] as a JSON list, published once when the line ends
#: (relative: ``/<unit>/transit``); kept for a late reader, outside the lockstep streams
TRANSIT = "transit"
TRANSIT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


#: a unit's view (relative topics: ``/<unit>/fence_state``, ``/<unit>/load_states``)
VIEW_FENCE = "fence_state"
VIEW_LOADS = "load_states"
#: slack on the view's sample times (the line view's rule: a sample at the first step
#: reaching each multiple of the period) [s]
VIEW_EPS = 1e-9


def handoff_latency_ns(info) -> int:
    """A hand-off's transit: the middleware's reception minus its writer's source timestamp
    (rclpy's message info, ns on the system clock: one clock on one host, synchronised
    clocks across hosts); -1 where either is missing."""
    try:
        return int(info["received_timestamp"]) - int(info["source_timestamp"])
    except (TypeError, KeyError, ValueError):
        return -1


def with_info(callback: Callable[[object, object], None]) -> Callable[..., None]:
    """``callback(msg, info)`` as a subscription callback: rclpy passes the message info to a
    callback of two arguments (its SingleThreadedExecutor calls ``(msg, info)``, its
    EventsExecutor passes the pair as one argument)."""

    def call(*args) -> None:
        msg, info = args if len(args) == 2 else args[0]
        callback(msg, info)

    call.__signature__ = _MSG_AND_INFO
    return call


def handoff_topic(unit_name: str) -> str:
    """The absolute topic a unit publishes its downstream hand-offs on."""
    return f"/{unit_name}/handoffs"


class LineUnitNode(FenceSorterNode):
    NODE_NAME = "line_unit"
    STATUS = "sorting"
    PARAMETERS = LINE_UNIT_PARAMETERS
    PINNED_CLOCK = False

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        p = self.parameter_values()
        line = load_line(p["line"])
        k = int(p["unit_index"])
        if k >= len(line.units):
            raise ValueError(
                f"unit_index: {k} out of range, the line has units 0..{len(line.units) - 1}"
            )
        cfg = LineRunConfig(dt=float(p["dt"]), guard=bool(p["guard"]))
        self.side = UnitSide(make_unit(line, k, cfg))
        upstream = INDUCTION_TOPIC if k == 0 else handoff_topic(line.units[k - 1].name)
        self.published = 0  # hand-offs published on the downstream link
        self.bad_messages = 0  # commands or hand-offs that could not be read (refused)
        self.ends_refused = 0  # 'end' before the owner's report: not the owner's (refused)
        self.started = False
        self.token = uuid.uuid4().hex[:12]
        self.upstream = upstream
        self.owner_timeout = float(p["owner_timeout"])
        self.last_command = time.monotonic()
        self.owner_gone = ""  # the line said when no command came for owner_timeout
        self.replies = self.create_publisher(String, "replies", LINE_QOS)
        self.handoffs = self.create_publisher(HandOffMsg, "handoffs", LINE_QOS)
        self.create_subscription(String, "commands", self._on_command, COMMAND_QOS)
        self.create_subscription(HandOffMsg, upstream, with_info(self._on_handoff), LINE_QOS)
        self.latency_ns: list[int] = []  # per hand-off arrived: DDS source -> received [ns]
        self.transit = self.create_publisher(String, TRANSIT, TRANSIT_QOS)
        self._ready_timer = self.create_timer(0.1, self._say_ready)
        self._owner_timer = self.create_timer(0.5, self._check_owner)
        self._view_setup(float(p["view_period"]), f"{line.units[k].name}/sorter")

    # -- the unit's view (view_period > 0) ------------------------------------------------------
    def _view_setup(self, period: float, frame_id: str) -> None:
        self.view_period = period
        self.view_samples = 0
        self._view_next = period
        self._view_frame = frame_id
        if period <= 0.0:
            return
        self._view_fence = self.create_publisher(FenceState, VIEW_FENCE, SENSOR_QOS)
        self._view_loads = self.create_publisher(LoadState, VIEW_LOADS, SENSOR_QOS)
        self._fence_msg, self._load_msg = FenceState(), LoadState()

    def _view_matched(self) -> bool:
        """With a view: its reader (the line's live view) has matched both view writers, so
        that it gets the samples from the line's start."""
        if self.view_period <= 0.0:
            return True
        return bool(
            self._view_fence.get_subscription_count() and self._view_loads.get_subscription_count()
        )

    def _view(self) -> None:
        """Publish the unit's view when its simulation (after a Step) has reached the next
        view sample time: each parcel in it on ``load_states``, then the fence."""
        if self.view_period <= 0.0:
            return
        sim = self.side.unit.line
        t = sim.t
        if t + VIEW_EPS < self._view_next:
            return
        late = math.floor((t + VIEW_EPS - self._view_next) / self.view_period) + 1
        self._view_next += self.view_period * max(1, late)
        snap = sim.snapshot()
        frame = self._view_frame
        for q in snap.parcels:
            self._view_loads.publish(fill_load_state(self._load_msg, q, snap.t, frame))
        self._view_fence.publish(fill_fence_state(self._fence_msg, snap.fence, snap.t, frame))
        self.view_samples += 1

    def _say_ready(self) -> None:
        """``ready<token>`` on replies while no command came, once both writers have matched
        and the owner's commands and the upstream link have a writer (with a view, once its
        writers have matched the live view's reader too)."""
        if self.started:
            self._ready_timer.cancel()
            return
        if (
            self.replies.get_subscription_count()
            and self.handoffs.get_subscription_count()
            and self.count_publishers(self.resolve_topic_name("commands"))
            and self.count_publishers(self.upstream)
            and self._view_matched()
        ):
            self.replies.publish(String(data=READY + self.token))

    def _check_owner(self) -> None:
        """Once the line runs: exit (EXIT_OWNER_GONE) when no command came for
        ``owner_timeout``."""
        if not self.started or self.owner_gone:
            return
        silent = time.monotonic() - self.last_command
        if silent > self.owner_timeout:
            self.owner_gone = (
                f"line_unit: no command from the line's owner for {silent:.1f} s "
                f"(owner_timeout {self.owner_timeout:g} s): its process or host is gone, or "
                "it took this unit for down"
            )
            rclpy.try_shutdown()

    def _on_command(self, msg: String) -> None:
        self.started = True
        self.last_command = time.monotonic()
        if msg.data == END and not self.side.reported:  # the owner ends after its report
            self.ends_refused += 1
            self.get_logger().error(
                "'end' refused: the line's owner ends a unit only after its report"
            )
            return
        if msg.data == END:
            self.get_logger().info("the line is over")
            self.transit.publish(String(data=json.dumps(self.latency_ns)))
            self.transit.wait_for_all_acked(Duration(seconds=10.0))
            for pub in (self.replies, self.handoffs):  # every reader (a recorder) has them
                pub.wait_for_all_acked(Duration(seconds=10.0))
            rclpy.try_shutdown()  # ends the spin: run_node returns 0
            return
        for text in split_batch(msg.data):
            try:
                cmd = decode(text)
            except (KeyError, TypeError, ValueError) as exc:
                self.bad_messages += 1
                self.get_logger().error(f"command refused: {type(exc).__name__}: {exc}")
                continue
            self._put(self.side.on_command(cmd))
        # the owner's silence counts from the unit's answer: a long command (the warm-up)
        # is the unit's own time, not the owner's
        self.last_command = time.monotonic()

    def _on_handoff(self, msg: HandOffMsg, info) -> None:
        self.latency_ns.append(handoff_latency_ns(info))
        self._put(self.side.on_handoff(handoff_from_msg(msg)))

    def _put(self, out: list[object]) -> None:
        for o in out:
            if isinstance(o, HandOff):
                self.handoffs.publish(handoff_to_msg(o))
                self.published += 1
            else:
                self.replies.publish(String(data=encode(o)))
        self._view()

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        u = self.side.unit
        values = {
            "handoffs_arrived": self.side.arrived,
            "handoffs_received": u.received,
            "handoffs_refused": sum(u.refused_handoffs.values()),
            "handoffs_lost": u.lost,
            "handoffs_sent": u.sent,
            "handoffs_published": self.published,
            "handoffs_foreign": self.side.foreign,
            "commands_applied": self.side.next_seq,
            "bad_messages": self.bad_messages,
            "ends_refused": self.ends_refused,
            "view_samples": self.view_samples,
        }
        status.values.extend(KeyValue(key=k, value=str(v)) for k, v in values.items())
        return status


class _Unit(LineUnitNode):
    """The unit :func:`main` ran (kept to read why it ended)."""

    last: LineUnitNode | None = None

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        _Unit.last = self


def main(args: Sequence[str] | None = None) -> int:
    """Run one unit until Ctrl-C, SIGTERM or the line's end; exit 2 with one line on a bad
    line file or index, EXIT_OWNER_GONE with one line when the owner fell silent."""
    try:
        code = run_node(_Unit, args)
    except ValueError as exc:
        print(f"line_unit: {exc}", file=sys.stderr)
        return 2
    node = _Unit.last
    if code == 0 and node is not None and node.owner_gone:
        print(node.owner_gone, file=sys.stderr)
        return EXIT_OWNER_GONE
    return code


if __name__ == "__main__":
    raise SystemExit(main())
