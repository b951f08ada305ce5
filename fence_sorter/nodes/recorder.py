"""Recorder node: every topic of the suite into a rosbag2 bag (MCAP by default, or sqlite3).

Subscriptions are raw (the CDR bytes pass through untouched) with the QoS each topic is
published with (best effort for the high-rate states, reliable for the rest). Callbacks only
stamp a message and queue it; a writer thread writes the queue into a
:class:`~fence_sorter.recording.writer.SegmentedBagWriter`, whose segments close every
``max_segment_duration`` seconds or ``max_segment_size_mb`` and whose open segment is flushed
(a complete, zstd-compressed MCAP chunk) every ``flush_period``, so a SIGKILL loses at most the
messages of the last ``flush_period`` and those still queued. SIGINT/SIGTERM drain the queue
and close the bag. Received, written and queued counts per topic are on /diagnostics.

The bag is ``output_dir`` itself when it does not exist or is empty (``fence-sorter run --bag
DIR``); otherwise a new ``output_dir/run_<UTC time>`` (never overwrites a bag). Bag timestamps
are this node's clock at reception (system time; sim time with ``use_sim_time:=true``, as
``ros2 bag record --use-sim-time``; ``fence-sorter run`` records on sim time, the clock of every
header stamp of the suite), except that on a topic whose messages start with a Header a
message is never logged after one stamped later
(:class:`~fence_sorter.recording.logtime.StampOrder`), so log time and header stamp agree on the
order of every topic (what ``rerun mcap check --full`` checks).
"""

from __future__ import annotations

import importlib
import json
import math
import os
import queue
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.parameter import Parameter
from rclpy.subscription import Subscription
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from fence_sorter.nodes.base import FenceSorterNode, run_node
from fence_sorter.nodes.parameters import RECORDER_PARAMETERS
from fence_sorter.nodes.qos import profile
from fence_sorter.recording.logtime import SettleBuffer, StampOrder, starts_with_header
from fence_sorter.recording.topics import (
    ALL_TOPICS,
    RECORDER_DEPTH,
    TOPICS,
    QosSpec,
    line_topics,
)
from fence_sorter.recording.writer import COMPRESSIONS, BagWriteError, SegmentedBagWriter

DEFAULT_TOPICS = list(TOPICS)
#: set when a recorder of this process failed to write or close its bag (exit status 1)
_WRITE_FAILED: list[str] = []
#: a message is held this long [s] before it is written, in log-time order (SettleBuffer)
SETTLE = 0.2


def bag_qos(spec: QosSpec) -> Qos:
    """The QoS stored with a topic in the bag: what its publisher offers (replay offers it
    again)."""
    zero = QosTime(0, 0)
    return Qos(
        QosHistory.KEEP_ALL if spec.keep_all else QosHistory.KEEP_LAST,
        spec.depth,
        QosReliability.RELIABLE if spec.reliable else QosReliability.BEST_EFFORT,
        QosDurability.TRANSIENT_LOCAL if spec.transient_local else QosDurability.VOLATILE,
        zero,
        zero,
        QosLiveliness.AUTOMATIC,
        zero,
        False,
    )


def message_class(msgtype: str) -> type:
    """'pkg/msg/Name' -> the generated rclpy class."""
    pkg, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def bag_path(output_dir: str) -> Path:
    """Where the bag goes: ``output_dir`` itself if it is missing or empty, else a new
    ``run_<UTC time>`` inside it; empty ``output_dir``: a new ``$ROS_HOME/bags/run_<UTC time>``
    (ROS_HOME defaults to ~/.ros)."""
    if output_dir:
        base = Path(output_dir).expanduser()
        if not base.exists() or (base.is_dir() and not any(base.iterdir())):
            return base
    else:
        base = Path(os.environ.get("ROS_HOME") or Path.home() / ".ros").expanduser() / "bags"
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    candidate = base / f"run_{stamp}"
    k = 1
    while candidate.exists():
        candidate = base / f"run_{stamp}_{k}"
        k += 1
    return candidate


def read_custom_data_file(path: str) -> dict[str, str]:
    """The string entries a JSON object file adds to the bag's metadata ``custom_data`` (what
    ``fence-sorter run --sensors`` knows of the truth); ValueError names the file."""
    if not path:
        return {}
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(f"recorder: custom_data_file {path}: cannot read: {exc}") from None
    if not isinstance(data, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in data.items()
    ):
        raise ValueError(
            f"recorder: custom_data_file {path}: must be a JSON object of strings to strings"
        )
    return data


@dataclass
class _Topic:
    name: str
    msgtype: str
    handle: int
    header: bool = False  # messages start with a std_msgs/Header
    received: int = 0
    written: int = 0
    not_written: int = 0  # after a write error (the bag ends there)
    subscription: Subscription | None = None


class RecorderNode(FenceSorterNode):
    """Bag recorder: subscribes raw (CDR passed through) and writes rosbag2 MCAP or sqlite3."""

    NODE_NAME = "recorder"
    #: logs on /clock as rosbag2 does: a message's log time is the sim time published before
    #: it on the wire (a second /clock shows in the log times, and the simulator names it)
    PINNED_CLOCK = False
    STATUS = "recording"
    PARAMETERS = RECORDER_PARAMETERS

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        p = self.parameter_values()
        self.path = bag_path(str(p["output_dir"]))
        self.writer = SegmentedBagWriter(
            self.path,
            storage=str(p["storage"]),
            max_segment_bytes=int(float(p["max_segment_size_mb"]) * 2**20),
            max_segment_duration=float(p["max_segment_duration"]),
            flush_period=float(p["flush_period"]),
            compression=str(p["compression"]),
            custom_data={
                "recorder": "fence_sorter",
                "node": self.get_fully_qualified_name(),
                **read_custom_data_file(str(p["custom_data_file"])),
            },
        ).open()
        self.stamp_order = StampOrder()
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._queued_max = 0
        self._lock = threading.Lock()
        self.write_error: str | None = None
        # the node's clock [s] (sim time in a run) when writing failed, and the newest log
        # time in the files then (the bag ends there)
        self.write_failed_at = math.nan
        self.bag_ends_at = math.nan
        self.topics: list[_Topic] = []
        units = [u.strip() for u in str(p["line_units"]).split(",") if u.strip()]
        # a line's recorder takes the line's topics (every unit's namespace), not ``topics``
        known = line_topics(units) if units else ALL_TOPICS
        for name in list(known) if units else p["topics"]:
            if name not in known:
                raise ValueError(
                    f"recorder: topics: {name} is not one of the suite's or measured topics "
                    f"({', '.join(ALL_TOPICS)})"
                )
            msgtype, spec = known[name].msgtype, known[name].qos
            handle = self.writer.add_topic(name, msgtype, [bag_qos(spec)])
            topic = _Topic(
                name, msgtype, handle, starts_with_header(self.writer.typestore, msgtype)
            )
            self.topics.append(topic)
            topic.subscription = self.create_subscription(
                message_class(msgtype),
                name,
                self._callback(topic),
                profile(spec.with_depth(max(RECORDER_DEPTH, spec.depth))),
                raw=True,
            )
        self._stop = threading.Event()
        self._started = time.monotonic()
        self._thread = threading.Thread(target=self._write_loop, name="recorder-writer")
        self._thread.start()
        self.get_logger().info(
            f"recording {len(self.topics)} topics into {self.path} ({p['storage']})"
        )

    # -- callbacks: stamp and hand off only -------------------------------------------------
    def _callback(self, topic: _Topic):
        put, clock = self._queue.put, self.get_clock()

        def on_message(data: bytes) -> None:
            topic.received += 1
            put((topic, clock.now().nanoseconds, data))

        return on_message

    # -- writer thread ------------------------------------------------------------------------
    def _write_loop(self) -> None:
        """Take the queue, give each message its log time (StampOrder), hold it SETTLE in log
        time order (SettleBuffer), write it; poll the writer (segments, flushes) when idle."""
        q, writer, log_time = self._queue, self.writer, self.stamp_order.log_time
        held = SettleBuffer(SETTLE)
        while True:
            try:
                item = q.get(timeout=0.05)
            except queue.Empty:
                item = None
            if item is not None:
                size = q.qsize() + 1
                if size > self._queued_max:
                    self._queued_max = size
                topic, t_ns, data = item
                if topic.header:
                    t_ns = log_time(topic.name, t_ns, data)
                held.push(t_ns, (topic, data))
            stopping = item is None and self._stop.is_set()
            for t_ns, (topic, data) in held.ready(everything=stopping):
                if self._guard(writer.write, topic.handle, t_ns, data):
                    topic.written += 1
                else:
                    topic.not_written += 1
            if item is None:
                if stopping:
                    break
                self._guard(writer.poll)
        # closed by this thread: a storage may be bound to the thread that opened it (sqlite3)
        try:
            writer.close()
        except Exception as exc:
            error = f"{type(exc).__name__}: {exc}"
            self.write_error = self.write_error or error
            print(f"[recorder] bag {self.path}: closing failed: {error}",
                  file=sys.stderr, flush=True)  # fmt: skip

    def _guard(self, func, *args) -> bool:
        if self.write_error is not None:
            return False
        try:
            func(*args)
            return True
        except Exception as exc:  # a full disk must not kill the node silently
            self.write_error = f"{type(exc).__name__}: {exc}"
            self.write_failed_at = self.get_clock().now().nanoseconds * 1e-9
            durable = self.writer.durable_ns
            self.bag_ends_at = durable * 1e-9 if durable is not None else math.nan
            self.get_logger().error(
                f"bag {self.path}: writing failed at t = {self.write_failed_at:.3f} s "
                f"(the bag holds every message up to t = {self.bag_ends_at:.3f} s, the last "
                f"flush; recording stops, the run goes "
                f"on): {self.write_error}"
            )
            try:  # the error on /diagnostics now, not at the next heartbeat
                self.publish_heartbeat()
            except Exception as pub_exc:  # the context may be going down
                print(f"[recorder] heartbeat not sent: {pub_exc}", file=sys.stderr, flush=True)
            return False

    def close(self) -> None:
        """Drain the queue, close the open segment and the bag (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join()  # the writer thread drains the queue and closes the bag
        if self.write_error is not None:
            _WRITE_FAILED.append(self.write_error)
        received = sum(t.received for t in self.topics)
        written = sum(t.written for t in self.topics)
        # printed, not logged: after SIGINT/SIGTERM the context (and /rosout) is already gone
        print(
            f"[recorder] bag {self.path} closed: {written} of {received} received messages "
            f"written in {len(self.writer.segments)} segments",
            file=sys.stderr,
            flush=True,
        )

    def destroy_node(self) -> None:
        self.close()
        super().destroy_node()

    # -- diagnostics ----------------------------------------------------------------------------
    def heartbeat_status(self) -> DiagnosticStatus:
        status = super().heartbeat_status()
        received = sum(t.received for t in self.topics)
        written = sum(t.written for t in self.topics)
        elapsed = max(time.monotonic() - self._started, 1e-9)
        values = {
            "bag": str(self.path),
            "storage": self.writer.storage,
            "segments_closed": str(len(self.writer.segments)),
            "compression": self.writer.compression,
            "flushes": str(self.writer.flushes),
            "received": str(received),
            "written": str(written),
            "queued": str(self._queue.qsize()),
            "queued_max": str(self._queued_max),
            "bytes_written": str(self.writer.bytes_written),
            "log_times_moved_to_stamp_order": str(self.stamp_order.adjusted),
            "write_rate_msgs_s": f"{written / elapsed:.1f}",
        }
        # topics with a publisher in the graph that this recorder's subscription has not yet
        # matched: what it publishes now is not recorded (the scanner's start gate waits)
        values["publishers_unmatched"] = " ".join(self.publishers_unmatched())
        # what it has matched, topic=count: the recorder's own graph may not yet show a
        # publisher that the scanner's does (the gate compares the counts with its graph)
        values["publishers_matched"] = " ".join(
            f"{t.name}={t.subscription.get_publisher_count()}" for t in self.topics
        )
        for t in self.topics:
            values[f"received{t.name.replace('/', '.')}"] = str(t.received)
            values[f"written{t.name.replace('/', '.')}"] = str(t.written)
        status.values.extend(KeyValue(key=k, value=v) for k, v in values.items())
        if self.write_error:
            status.level = DiagnosticStatus.ERROR
            status.message = f"writing failed: {self.write_error}"
            status.values.extend(
                KeyValue(key=k, value=v)
                for k, v in {
                    "write_error": self.write_error,
                    "write_failed_at_sim_s": f"{self.write_failed_at:.3f}",
                    "bag_ends_sim_s": f"{self.bag_ends_at:.3f}",
                    "messages_dropped_write_failed": str(sum(t.not_written for t in self.topics)),
                }.items()
            )
        return status

    def publishers_unmatched(self) -> list[str]:
        """The recorded topics on which the graph holds more publishers than this recorder's
        subscription has matched."""
        return [
            t.name
            for t in self.topics
            if self.count_publishers(t.name) > t.subscription.get_publisher_count()
        ]

    def validate_parameters(self, parameters: Sequence[Parameter]) -> str | None:
        for param in parameters:
            if param.name == "storage" and param.value not in ("mcap", "sqlite3"):
                return f"storage must be mcap or sqlite3, got {param.value!r}"
            if param.name == "compression" and param.value not in COMPRESSIONS:
                return f"compression must be zstd or none, got {param.value!r}"
        return None


def main(args: Sequence[str] | None = None) -> int:
    """Run the recorder until Ctrl-C or SIGTERM; the bag is closed on the way out. Exit 1 if
    writing or closing the bag failed, 2 with one line when the bag cannot be created or a topic
    is unknown."""
    try:
        code = run_node(RecorderNode, args)
        return 1 if code == 0 and _WRITE_FAILED else code
    except (ValueError, BagWriteError) as exc:
        print(f"recorder: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
