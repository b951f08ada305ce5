"""The run's own rclpy node: listens to /parcels, /fence_commands, /sort_outcomes, /diagnostics
and /scan_progress, and keeps plain records for :mod:`fence_sorter.runner.summary`.

With a ``run_id``, parcels and commands of another run (another ``run_id`` on the message) are
counted apart as foreign and never enter the records the figures come from. With the run's key
(:mod:`fence_sorter.provenance`), so are messages with the run's id whose sender's tag does not
verify (forged, by parcel id). With the run's stream, a parcel outside it is counted apart, and
one whose spec differs from the stream's (or from an earlier message's) is disputed."""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field, replace

from fence_sorter.codes import OutcomeCode, code_name
from fence_sorter.inputs import ParcelSpec
from fence_sorter.nodes.intake import spec_fingerprint
from fence_sorter.recording import topics
from fence_sorter.stamps import time_to_sec

#: the monitor's node name (the scanner's start gate waits for its subscriptions)
MONITOR_NAME = "fence_sorter_run"
#: the /diagnostics status names of the run's nodes (``fence_sorter/<node>``): a status so
#: named must carry its node's tag under the run's key
RUN_STATUS_PREFIX = "fence_sorter/"


@dataclass
class Records:
    """What the monitor saw (plain data, no messages)."""

    sim_time: float = 0.0
    parcels: dict[int, dict] = field(default_factory=dict)
    parcel_messages: int = 0
    foreign_parcel_messages: int = 0
    foreign_command_messages: int = 0
    #: messages with the run's id whose tag did not verify under the run's key, by parcel id
    forged_parcels: dict[int, int] = field(default_factory=dict)
    forged_commands: dict[int, int] = field(default_factory=dict)
    forged_outcomes: dict[int, int] = field(default_factory=dict)
    foreign_outcome_messages: int = 0
    #: /diagnostics statuses named as a node of the run whose tag did not verify, by name
    forged_diagnostics: dict[str, int] = field(default_factory=dict)
    #: authentic statuses older than one already taken from the same node process (a replay)
    stale_diagnostics: int = 0
    #: authentic parcel messages of ids outside the run's stream
    unexpected_parcel_messages: int = 0
    #: parcel ids given two specs (two authentic messages, or a message and the stream)
    disputed: set[int] = field(default_factory=set)
    commands: dict[int, dict] = field(default_factory=dict)
    command_messages: int = 0
    outcomes: dict[int, dict] = field(default_factory=dict)
    outcome_messages: int = 0
    diagnostics: dict[str, dict[str, str]] = field(default_factory=dict)
    diagnostics_history: dict[str, list[dict[str, str]]] = field(default_factory=dict)


class Monitor:
    """An rclpy context and node of its own (no signal handlers: the job handles Ctrl-C)."""

    def __init__(
        self,
        domain_id: int,
        name: str = MONITOR_NAME,
        run_id: int = 0,
        run_key: bytes | None = None,
        stream: dict[int, ParcelSpec] | None = None,
    ):
        # Records and the runner's checks of its input do without ROS
        import rclpy  # lazy: rclpy, ~0.1-0.4 s, once the run starts
        from diagnostic_msgs.msg import DiagnosticArray  # lazy: ROS message
        from rclpy.qos import QoSProfile, ReliabilityPolicy  # lazy: rclpy
        from rclpy.signals import SignalHandlerOptions  # lazy: rclpy
        from rosgraph_msgs.msg import Clock  # lazy: ROS message

        from fence_sorter.nodes import convert, sources  # lazy: rclpy
        from fence_sorter.nodes.base import make_executor  # lazy: rclpy
        from fence_sorter.nodes.qos import INPUT_QOS, topic_qos  # lazy: rclpy
        from fence_sorter_msgs.msg import FenceCommand, Parcel, SortOutcome  # lazy: ROS messages

        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(
            context=self.context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self.node = rclpy.create_node(name, context=self.context)
        self.records = Records()
        self.run_id = int(run_id)
        self.run_key = run_key
        self.stream = stream
        self._authentic = sources.authentic
        self._status_authentic = sources.status_authentic
        self._status_order = sources.status_order
        self._status_stamps: dict[str, tuple[int, float]] = {}
        self._parcel_from_msg = convert.parcel_from_msg
        self._specs: dict[int, tuple[str, ...]] = {}
        n = self.node
        for msg_type, name, callback in (
            (Parcel, topics.PARCELS, self._on_parcel),
            (FenceCommand, topics.FENCE_COMMANDS, self._on_command),
            (SortOutcome, topics.SORT_OUTCOMES, self._on_outcome),
            (DiagnosticArray, topics.DIAGNOSTICS, self._on_diag),
        ):
            inputs = name in (topics.PARCELS, topics.FENCE_COMMANDS)
            qos = INPUT_QOS if inputs else topic_qos(name)
            n.create_subscription(msg_type, name, callback, qos)
        # sim time from the scanner's progress (5 per sim second), the simulator's heartbeat and
        # the outcomes, not /clock: an unpaced run sends thousands of /clock messages per
        # second, and taking them cost this process a third of a core
        n.create_subscription(
            Clock,
            topics.SCAN_PROGRESS,
            self._on_progress,
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
        )
        self.executor = make_executor(True, context=self.context)
        self.executor.add_node(self.node)

    # -- callbacks (record only) -----------------------------------------------------------
    def _seen(self, t: float) -> None:
        """Sim time reached, as far as the monitor knows (monotonic)."""
        if t > self.records.sim_time:
            self.records.sim_time = t

    def _on_progress(self, msg) -> None:
        self._seen(time_to_sec(msg.clock))

    def _foreign(self, msg) -> bool:
        return bool(self.run_id) and int(msg.run_id) != self.run_id

    def _forged(self, msg, counts: dict[int, int]) -> bool:
        """A message with the run's id that its sender's tag does not vouch for (counted)."""
        if self._authentic(msg, self.run_key):
            return False
        pid = int(msg.parcel_id)
        counts[pid] = counts.get(pid, 0) + 1
        return True

    def _disputed(self, msg) -> bool:
        """Whether this parcel message contradicts the stream or an earlier message."""
        spec = self._parcel_from_msg(msg)
        pid = spec.parcel_id
        mine = spec_fingerprint(physical(spec))
        if pid in self._specs:
            return self._specs[pid] != mine
        self._specs[pid] = mine
        return self.stream is not None and spec_fingerprint(physical(self.stream[pid])) != mine

    def _on_parcel(self, msg) -> None:
        r = self.records
        if self._foreign(msg):
            r.foreign_parcel_messages += 1
            return
        if self._forged(msg, r.forged_parcels):
            return
        if self.stream is not None and int(msg.parcel_id) not in self.stream:
            r.unexpected_parcel_messages += 1
            return
        if self._disputed(msg):
            r.disputed.add(int(msg.parcel_id))
        r.parcel_messages += 1
        r.parcels.setdefault(
            int(msg.parcel_id),
            {
                "scan_time": time_to_sec(msg.scan_time),
                "scan_position_x": msg.scan_position_x,
                "divert": bool(msg.divert),
                "length_a": msg.length_a,
                "width_b": msg.width_b,
                "yaw": msg.yaw,
                "mass": msg.mass,
                "wall": time.monotonic(),
                "received_sim": r.sim_time,
            },
        )

    def _on_command(self, msg) -> None:
        r = self.records
        if self._foreign(msg):
            r.foreign_command_messages += 1
            return
        if self._forged(msg, r.forged_commands):
            return
        r.command_messages += 1
        r.commands.setdefault(
            int(msg.parcel_id),
            {
                "feasible": bool(msg.feasible),
                "reason": msg.reason,
                "r_s": msg.r_s,
                "t1": msg.t1,
                "alpha_k": msg.alpha_k,
                "stamp": time_to_sec(msg.header.stamp),
                "received_sim": r.sim_time,
                "wall": time.monotonic(),
                "predicted_capacity_pcs_h": msg.predicted_capacity_pcs_h,
                "predicted_peak_accel": msg.predicted_peak_accel,
                "predicted_impact_speed": msg.predicted_impact_speed,
                "predicted_exit_speed": msg.predicted_exit_speed,
            },
        )

    def _on_outcome(self, msg) -> None:
        r = self.records
        if self._foreign(msg):
            r.foreign_outcome_messages += 1
            return
        if self._forged(msg, r.forged_outcomes):
            return
        r.outcome_messages += 1
        r.outcomes.setdefault(
            int(msg.parcel_id),
            {
                "sorted": bool(msg.sorted),
                "reason": msg.reason,
                "reason_code": int(msg.reason_code),
                "reason_name": code_name(OutcomeCode, msg.reason_code),
                "time": time_to_sec(msg.header.stamp),
                "peak_normal_force": msg.peak_normal_force,
                "peak_normal_force_stiff": msg.peak_normal_force_stiff,
                "peak_normal_accel": msg.peak_normal_accel,
                "impact_normal_speed": msg.impact_normal_speed,
                "exit_speed_y": msg.exit_speed_y,
                "disputed": bool(getattr(msg, "disputed", False)),
            },
        )
        self._seen(time_to_sec(msg.header.stamp))

    def _on_diag(self, msg) -> None:
        r = self.records
        stamp = time_to_sec(msg.header.stamp)
        for status in msg.status:
            if self.run_key is not None and status.name.startswith(RUN_STATUS_PREFIX):
                if not self._status_authentic(msg.header.stamp, status, self.run_key):
                    r.forged_diagnostics[status.name] = (
                        r.forged_diagnostics.get(status.name, 0) + 1
                    )
                    continue
                order = self._status_order(stamp, status)
                if order < self._status_stamps.get(status.name, (-1, -math.inf)):
                    r.stale_diagnostics += 1
                    continue
                self._status_stamps[status.name] = order
            values = {kv.key: kv.value for kv in status.values}
            values["_message"] = status.message
            values["_level"] = (
                str(int.from_bytes(status.level, "little"))
                if isinstance(status.level, bytes)
                else str(status.level)
            )
            values["_wall"] = f"{time.monotonic():.6f}"
            r.diagnostics[status.name] = values
            r.diagnostics_history.setdefault(status.name, []).append(values)
            if status.name == "fence_sorter/simulator" and "sim_time_s" in values:
                try:
                    self._seen(float(values["sim_time_s"]))
                except ValueError:
                    pass

    # -- driving ---------------------------------------------------------------------------
    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while True:
            left = end - time.monotonic()
            if left <= 0:
                break
            self.executor.spin_once(timeout_sec=min(left, 0.05))

    def node_diag(self, node: str) -> dict[str, str] | None:
        return self.records.diagnostics.get(f"fence_sorter/{node}")

    def close(self) -> None:
        try:
            self.executor.shutdown()
            self.node.destroy_node()
        finally:
            self.rclpy.try_shutdown(context=self.context)


def physical(spec: ParcelSpec) -> ParcelSpec:
    """The spec without its times and scan position (what the stream fixes of a parcel)."""
    return replace(spec, scan_time=0.0, scan_position_x=0.0, arrival_time=0.0)
