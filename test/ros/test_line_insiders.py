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
import os
import re
import signal
import subprocess
import sys
import threading
import uuid
from pathlib import Path

import pytest
from processes import run_cli, stop_process, wait_until

from fence_sorter.line.lockstep import DELIVERED_PREFIX, Done, encode

from .test_line_unit_killed import LINE, PARCELS, RATE, REPO, RTF, SEED, TAG, _pid

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
    tag = uuid.uuid4().hex
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env[TAG] = tag
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--line", LINE, "--parcels",
           str(PARCELS), "--seed", str(SEED), "--rate", str(RATE), "--rtf", str(RTF), "--json",
           "--log-dir", str(tmp_path / "logs"), "--reply-timeout", "60",
           "--owner-timeout", "90"]  # fmt: skip
    err_file = tmp_path / "stderr.txt"
    insider, held = None, None
    with err_file.open("w") as err_out:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=err_out, text=True, cwd=REPO, env=env,
            start_new_session=True,
        )  # fmt: skip
        try:
            found = wait_until(
                lambda: (
                    re.search(r"ROS domain (\d+)", err_file.read_text()) or proc.poll() is not None
                ),
                120.0,
                "the runner's domain",
            )
            assert proc.poll() is None, err_file.read_text()
            # the owner held until the insider matched unit_2's topics
            owner = wait_until(
                lambda: _pid(tag, "fence_sorter.nodes.line_owner"), 60.0, "the owner's process"
            )
            os.kill(owner, signal.SIGSTOP)
            held = owner
            insider = _Insider(int(found.group(1)))
            wait_until(
                lambda: (
                    insider.commands.get_subscription_count() > 0
                    and insider.replies.get_subscription_count() > 0
                    and insider.sub.get_publisher_count() > 0
                ),
                120.0,
                "unit_2's topics matched",
            )
            os.kill(owner, signal.SIGCONT)
            held = None
            wait_until(
                lambda: insider.running or proc.poll() is not None, 240.0, "the line running"
            )
            insider.strike()
            out, _ = proc.communicate(timeout=300)
        finally:
            if held is not None:
                os.kill(held, signal.SIGCONT)
            if insider is not None:
                insider.close()
            stop_process(proc)
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
