"""What a line's owner does for its bag (``fence-sorter run --line --bag DIR``).

- :class:`RecorderGate`: the owner's start gate also waits until the recorder reports (its
  heartbeat on /diagnostics, ``publishers_matched``) that it matched the one publisher of every
  lockstep topic of the line: the lockstep topics are volatile, and what is published before
  the recorder matched would be missing from the bag (the replay of
  :mod:`fence_sorter.analysis.line_bag` needs every reply of every unit).
- :func:`publish_setup`: the line file (name and text) and the run's configuration, once at
  the start on /line/setup (reliable, transient local): the bag holds what the owner ran.
- :func:`publish_summary`: the line summary the run prints, once on /line/summary (reliable,
  transient local), waited for until every reader (the recorder) acknowledged it, so the bag
  holds the live summary beside the records it is computed from.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import String

from fence_sorter.jsonsafe import json_safe
from fence_sorter.nodes.qos import profile, topic_qos
from fence_sorter.recording.topics import (
    CLOCK,
    DIAGNOSTICS,
    LINE_SETUP,
    LINE_SUMMARY,
    LINE_SUMMARY_QOS,
    line_topics,
)

#: the recorder's status name on /diagnostics
RECORDER_STATUS = "fence_sorter/recorder"


class RecorderGate:
    """Which topics of the line the recorder has not matched yet (its latest heartbeat);
    /clock and /diagnostics are not waited for (the replay does not need them)."""

    def __init__(self, node: Node, units: list[str]):
        self.wanted = [t for t in line_topics(units) if t not in (CLOCK, DIAGNOSTICS)]
        self.matched: dict[str, int] = {}
        self.heard = False
        node.create_subscription(
            DiagnosticArray, DIAGNOSTICS, self._on_diagnostics, topic_qos(DIAGNOSTICS)
        )

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name != RECORDER_STATUS:
                continue
            values = {kv.key: kv.value for kv in status.values}
            if "publishers_matched" not in values:
                continue
            matched = {}
            for item in values["publishers_matched"].split():
                topic, _, count = item.rpartition("=")
                matched[topic] = int(count)
            self.matched = matched
            self.heard = True

    def missing(self) -> list[str]:
        """``recorder`` until its first report, then ``recorder:<topic>`` per topic whose
        publisher it has not matched."""
        if not self.heard:
            return ["recorder"]
        return [f"recorder:{t}" for t in self.wanted if self.matched.get(t, 0) < 1]


def summary_publisher(node: Node):
    """The owner's /line/summary publisher (created at start: the recorder's gate sees it)."""
    return node.create_publisher(String, LINE_SUMMARY, profile(LINE_SUMMARY_QOS))


def publish_summary(pub, summary: dict, timeout: float = 10.0) -> bool:
    """The summary as JSON on /line/summary; True once every reader acknowledged it."""
    pub.publish(String(data=json.dumps(json_safe(summary))))
    return bool(pub.wait_for_all_acked(Duration(seconds=timeout)))


def publish_setup(node: Node, line_path: Path, cfg: object, warm_up: bool):
    """Publish the owner's set-up on /line/setup (kept for late joiners); returns the
    publisher, which must live as long as the node."""
    pub = node.create_publisher(String, LINE_SETUP, profile(LINE_SUMMARY_QOS))
    setup = {
        "line_file": line_path.name,
        "line_text": line_path.read_text(encoding="utf-8"),
        "config": asdict(cfg),
        "warm_up": bool(warm_up),
    }
    pub.publish(String(data=json.dumps(json_safe(setup))))
    return pub
