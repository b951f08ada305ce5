"""An insider on a line's wire: ``end`` written to a unit's command topic and a reply the
owner never asked for written to its reply topic, while ``run --line two_units`` runs.

The unit takes ``end`` only after the owner's report (the last command of a line), so it
refuses this one and stays in the line; the owner refuses the forged reply (it answers no
question it asked), names it in the summary and the run is not clean (exit 1). Everything
else is the undisturbed line's: its summary equals ``line-sim``'s for the same line, stream
and seed, field by field, and no unit restarted.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest
from processes import run_cli, wait_until

from fence_sorter.line.lockstep import DELIVERED_PREFIX, Done, encode

from .line_process import LINE, PARCELS, RATE, SEED, held_line_run

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.faults]


class _Insider:
    """Publishers on ``/unit_2/commands`` and ``/unit_2/replies`` and a subscriber that sees
    the line run (unit_2's first Delivered reply), in a context of its own."""

    def __init__(self, domain: int):
        import rclpy  # lazy: rclpy only for the ROS tests
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        from std_msgs.msg import String

        from fence_sorter.nodes.line_unit import COMMAND_QOS, LINE_QOS

        self.rclpy, self.String = rclpy, String
        self.context = rclpy.Context()
        rclpy.init(
            context=self.context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO
        )
        self.node = rclpy.create_node("line_insider", context=self.context)
        self.commands = self.node.create_publisher(String, "/unit_2/commands", COMMAND_QOS)
        self.replies = self.node.create_publisher(String, "/unit_2/replies", LINE_QOS)
        self.running = False
        self.sub = self.node.create_subscription(
            String, "/unit_2/replies", self._on_reply, LINE_QOS
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _on_reply(self, msg) -> None:
        self.running = self.running or msg.data.startswith(DELIVERED_PREFIX)

    def strike(self) -> None:
        self.commands.publish(self.String(data="end"))
        self.replies.publish(self.String(data=encode(Done(-1.0, (), ()))))

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # the context shut down under it
            pass

    def close(self) -> None:
        self.rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=10.0)
        self.executor.shutdown()
        self.node.destroy_node()


def test_a_forged_end_and_an_unasked_reply_change_no_figure_and_are_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log_insider"))

    def matched(insider: _Insider) -> bool:
        return (
            insider.commands.get_subscription_count() > 0
            and insider.replies.get_subscription_count() > 0
            and insider.sub.get_publisher_count() > 0
        )

    with held_line_run(tmp_path, lambda domain, tag: _Insider(domain), matched) as (
        proc,
        insider,
        err_file,
    ):
        wait_until(lambda: insider.running or proc.poll() is not None, 240.0, "the line running")
        insider.strike()
        out, _ = proc.communicate(timeout=300)
    err = err_file.read_text()
    assert proc.returncode == 1 and "Traceback" not in err, err
    s = json.loads(out)
    assert s["restarts"] == {"unit_1": 0, "unit_2": 0} and not s["units_down"], s["units_down"]
    assert s["replies_refused"] == {"unit_2": ["Done -1.0"]}, s["replies_refused"]
    sim = run_cli("line-sim", LINE, "--parcels", str(PARCELS), "--seed", str(SEED), "--rate",
                  str(RATE), "--json")  # fmt: skip
    assert sim.returncode == 0, sim.stderr
    ref = json.loads(sim.stdout)
    wall = ("wall_time_s", "real_time_factor")
    assert {k: (v, s.get(k)) for k, v in ref.items() if k not in wall and s.get(k) != v} == {}
