"""A unit's process of ``fence-sorter run --line`` killed (SIGKILL) while one of its strokes
runs, the moment chosen from what is on the wire.

``run --line two_units`` runs as the user starts it (its own processes on a domain it chose,
the line clock paced at ``RTF``); a subscriber in the test reads ``/unit_2/replies`` and, as
soon as a reply books a stroke on unit_2 (a ``Delivered`` with a booking), SIGKILLs unit_2's
process. The line clock is then still well before the stroke's end: the owner needs unit_2's
answer to every step, and on this stream the stroke booked first on unit_2 ends 4.2 s of sim
time after its booking (``line-sim``), at least 2 s of wall time at ``RTF``. The line must go
on: the runner starts the unit
again (``restarts``), the owner takes the old process for down when the new one says ready
with its own token, passes the unit's hand-offs on meanwhile and lets the new process rejoin
at a step. Checked: the parcel in that stroke is lost with the unit and named, conservation is
exact with it counted, every link balances at both ends, exit 0, the unit down once and back
once after one step of sim time, its new process sorting again.
"""

from __future__ import annotations

import json
import os
import signal
import threading
from pathlib import Path

import pytest
from processes import wait_until

from fence_sorter.line.lockstep import DELIVERED_PREFIX, Delivered, decode

from .line_process import PARCELS, held_line_run, run_pid

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.faults]

#: on the line of line_process (two_units, 6 parcels, seed 3, 4000 pcs/h, rtf 2), parcel 6 is
#: the first unit_2 books a stroke for; parcels announced after its new process rejoined go
#: to it
DT = 0.01  # the line clock's step [s]


class _Killer:
    """A subscriber on ``/unit_2/replies`` in the test process (a context of its own, spun in
    a thread of its own, reading only the Delivered replies): kills unit_2's process ``pid``
    when a reply first books a stroke on it."""

    def __init__(self, domain: int, pid: int):
        import rclpy  # lazy: rclpy only for the ROS tests
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        from std_msgs.msg import String

        from fence_sorter.nodes.line_unit import LINE_QOS

        self.rclpy, self.pid = rclpy, pid
        self.context = rclpy.Context()
        rclpy.init(
            context=self.context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO
        )
        self.node = rclpy.create_node("line_kill_listener", context=self.context)
        self.booking = None  # the booking unit_2's first process was killed in
        self.sub = self.node.create_subscription(
            String, "/unit_2/replies", self._on_reply, LINE_QOS
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _on_reply(self, msg) -> None:
        # a step's answer (Done) or a ready: no booking; only a Delivered is read
        if self.booking is not None or not msg.data.startswith(DELIVERED_PREFIX):
            return
        r = decode(msg.data)
        if isinstance(r, Delivered) and r.booking is not None:
            os.kill(self.pid, signal.SIGKILL)
            self.booking = r.booking

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # the context shut down under it
            pass

    def close(self) -> None:
        self.rclpy.try_shutdown(context=self.context)  # ends the spin
        self.thread.join(timeout=10.0)
        self.executor.shutdown()
        self.node.destroy_node()


def test_a_unit_killed_in_a_stroke_loses_that_parcel_and_rejoins(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log_listener"))

    def killer(domain: int, tag: str) -> _Killer:
        unit_2 = run_pid(tag, "fence_sorter.nodes.line_unit", "unit_index:=1")
        assert unit_2 is not None
        return _Killer(domain, unit_2)

    # the owner's clock waits for the killed unit's new process, however slow its start on a
    # loaded machine, and the other unit waits for the owner as long
    with held_line_run(tmp_path, killer, lambda k: k.sub.get_publisher_count() > 0) as (
        proc,
        k,
        err_file,
    ):
        wait_until(
            lambda: k.booking is not None or proc.poll() is not None,
            240.0,
            "a stroke booked on unit_2",
        )
        b = k.booking
        assert b is not None, err_file.read_text()
        out, _ = proc.communicate(timeout=300)
    err = err_file.read_text()
    assert b.unit == 1 and b.t_start < b.t_end, b
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert "unit_2 ended during the run (exit -9); starting it again (1 of at most 3)" in err
    s = json.loads(out)
    assert s["restarts"] == {"unit_1": 0, "unit_2": 1}
    down = s["units_down"]["unit_2"]
    assert down["downs"] == 1 == down["rejoins"] and not down["down_at_end"], down
    assert "a new process of it started" in down["why"]
    assert "unit_1" not in s["units_down"]
    # the parcel of the stroke the kill cut, and only it, is lost with the unit, named with it
    assert down["lost_parcels"] == [b.parcel_id] and s["lost_with_unit"] == 1
    # conservation exact: every parcel inducted ended, or was lost with the unit
    assert s["drained"] and s["conservation_ok"] and s["handoffs_balanced"], s
    assert s["still_on_line"] == 0
    assert (
        PARCELS
        == s["parcels_inducted"]
        == s["sorted"] + s["rejected"] + s["solver_failures"] + s["lost_with_unit"]
    )
    # every hand-off on every link counted at both ends (the dead process's counts kept)
    for link, v in s["links"].items():
        assert v["sent"] == v["received"] + sum(v["refused"].values()) + v["lost"], link
    # the stand-in's hand-offs are the unit's declines `unit_down`
    assert s["units"]["unit_2"]["declined"]["unit_down"] == down["handoffs_passed_on"]
    # the clock waited for the new process: down one step of sim time (its wall time is the
    # restart's, beside it)
    assert down["downtime_s"] == pytest.approx(DT, abs=1e-9)
    assert down["downtime_wall_s"] >= 0.0
    # the new process routed the parcels announced after it rejoined and sorted again
    assert down["sorted_by_last_process"] > 0
