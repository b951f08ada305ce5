"""Foxglove node: every topic of the run to the Foxglove app over the Foxglove WebSocket protocol.

Raw subscriptions (the CDR bytes as they came over DDS) with the QoS each topic is published
with, forwarded unchanged on ``ros2msg``/``cdr`` channels of a Foxglove WebSocket server
(:class:`fence_sorter.visualisation.foxglove_live.LiveServer`): /tf, /tf_static,
/robot_description, /joint_states and /markers give Foxglove's 3D panel the sorter, the other
topics its plots and tables. /clock is the server's time. The server binds ``host`` (default
127.0.0.1, this machine only: docs/design/security.md) and ``port``; clients, forwarded messages
and, per client, the messages handed to its queue, sent, and dropped when its queue of
``client_backlog`` was full (exact counts: docs/guide/foxglove.md) are on /diagnostics.
``fence-sorter run --foxglove [HOST:]PORT`` starts it in a process of its own.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.event_handler import SubscriptionEventCallbacks, UnsupportedEventTypeError
from rclpy.parameter import Parameter

from fence_sorter.nodes.base import FenceSorterNode, run_node
from fence_sorter.nodes.parameters import FOXGLOVE_PARAMETERS
from fence_sorter.nodes.qos import topic_qos
from fence_sorter.nodes.recorder import message_class
from fence_sorter.recording.msgtypes import make_typestore
from fence_sorter.recording.topics import ALL_TOPICS, CLOCK, FOXGLOVE_DEPTH
from fence_sorter.visualisation.foxglove_address import AddressError, parse_address
from fence_sorter.visualisation.foxglove_live import LiveServer


class ServeError(RuntimeError):
    """The server cannot start (one line: the address and the reason)."""


class FoxgloveNode(FenceSorterNode):
    """Serves the run's topics to Foxglove (Foxglove WebSocket server, ros2msg/cdr)."""

    NODE_NAME = "foxglove"
    STATUS = "serving"
    PARAMETERS = FOXGLOVE_PARAMETERS

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        p = self.parameter_values()
        for name in p["topics"]:
            if name not in ALL_TOPICS:
                raise ValueError(
                    f"topics: {name} is not one of the suite's or measured topics "
                    f"({', '.join(ALL_TOPICS)})"
                )
        host, port = str(p["host"]), int(p["port"])
        self.server: LiveServer | None = None
        try:
            self.server = LiveServer(
                make_typestore(), host=host, port=port, backlog=int(p["client_backlog"])
            )
        except RuntimeError as exc:  # foxglove_ws.ServeError: a port in use, no such address
            raise ServeError(f"cannot serve on {host}:{port}: {exc}") from None
        self.lost = 0  # messages the middleware reports lost before this node took them
        self.served_subscriptions = []
        for name in p["topics"]:
            topic = ALL_TOPICS[name]
            self.server.add_topic(name, topic.msgtype)
            qos = topic_qos(name, max(FOXGLOVE_DEPTH, topic.qos.depth))
            callback = self._callback(name)
            try:
                sub = self.create_subscription(
                    message_class(topic.msgtype),
                    name,
                    callback,
                    qos,
                    raw=True,
                    event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost),
                )
            except UnsupportedEventTypeError:
                sub = self.create_subscription(
                    message_class(topic.msgtype), name, callback, qos, raw=True
                )
            self.served_subscriptions.append(sub)
        self.get_logger().info(
            f"Foxglove WebSocket server on ws://{host}:{self.server.port} "
            f"({len(self.served_subscriptions)} topics)"
        )

    def _callback(self, name: str):
        log, clock = self.server.log, self.get_clock()
        if name == CLOCK:
            broadcast = self.server.broadcast_time

            def on_clock(data: bytes) -> None:
                t_ns = clock.now().nanoseconds
                log(name, data, t_ns)
                broadcast(t_ns)

            return on_clock

        def on_message(data: bytes) -> None:
            log(name, data, clock.now().nanoseconds)

        return on_message

    def _on_lost(self, info) -> None:
        self.lost += int(info.total_count_change)

    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        values = {**self.server.stats(), "lost_before_taken": str(self.lost)}
        status.values.extend(KeyValue(key=k, value=v) for k, v in values.items())
        if values["dropped"] != "0":
            status.level = DiagnosticStatus.WARN
            status.message = (
                f"serving; {values['slow_clients']} slow clients lost {values['dropped']} "
                f"messages (queue of {self.server.backlog} full)"
            )
        return status

    def validate_parameters(self, parameters: Sequence[Parameter]) -> str | None:
        for param in parameters:
            if param.name == "host":
                try:
                    parse_address(f"{param.value}:1", "parameter host")
                except AddressError as exc:
                    return str(exc)
        return None

    def destroy_node(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None
        super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    """Serve until Ctrl-C or SIGTERM; 2 with one line when the server cannot start (the port
    is taken) or a topic is unknown."""
    try:
        return run_node(FoxgloveNode, args)
    except (ValueError, ServeError) as exc:
        print(f"foxglove: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
