"""A line over DDS: two ``line_unit`` processes (namespaces /unit_1, /unit_2) and the
``line_owner`` process, real rclpy nodes talking over Fast DDS on an isolated domain.

The owner's lockstep clock makes the line's figures those of the in-process line on the same
stream and seed, exactly; every hand-off is counted at both ends of its link.
"""

from __future__ import annotations

import json
import subprocess
import sys
from contextlib import ExitStack

import pytest
from processes import managed_process, wait_until

from fence_sorter.jsonsafe import json_safe
from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TWO = load_line("two_units")
WALL = ("wall_time_s", "real_time_factor")


def _node(name: str, *ros_args: str) -> list[str]:
    return [sys.executable, "-m", f"fence_sorter.nodes.{name}", "--ros-args", *ros_args]


@pytest.fixture
def diagnostics(domain_id: int, tmp_path, monkeypatch: pytest.MonkeyPatch):
    """A listener on /diagnostics in the test process (own context) and what it got."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from fence_sorter.nodes.qos import RELIABLE_QOS

    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log_listener"))
    context = rclpy.Context()
    rclpy.init(
        context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO
    )
    node = rclpy.create_node("line_listener", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    received: list = []
    node.create_subscription(DiagnosticArray, "/diagnostics", received.append, RELIABLE_QOS)
    try:
        yield executor, received
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _beat(received: list, node: str) -> dict | None:
    """The values of the newest heartbeat of ``node`` (its fully qualified name)."""
    for msg in reversed(received):
        for st in msg.status:
            values = {v.key: v.value for v in st.values}
            if values.get("node") == node:
                return values
    return None


def test_two_units_over_dds_give_the_in_process_line_s_figures(env, tmp_path, diagnostics):
    """10 parcels on two_units, seed 3: the owner's summary equals LinePlant's field by field
    (wall-clock fields aside), the line drained with conservation exact, on every link as
    many hand-offs were received as sent, and each unit's heartbeat on /diagnostics counts
    the same at its ends of the links: as many arrived on its upstream topic as it received,
    as many published on its downstream topic as it sent."""
    executor, received = diagnostics
    cfg = LineRunConfig(parcels=10, seed=3)
    ref = json_safe(LinePlant(TWO, cfg).run())
    out = tmp_path / "summary.json"
    beat = ["-p", "heartbeat_period:=0.2"]
    with ExitStack() as stack:
        for k, u in enumerate(TWO.units):
            stack.enter_context(
                managed_process(
                    _node(
                        "line_unit",
                        "-r",
                        f"__ns:=/{u.name}",
                        "-p",
                        f"unit_index:={k}",
                        "-p",
                        "line:=two_units",
                        *beat,
                    ),  # fmt: skip
                    env,
                    stdout=subprocess.DEVNULL,
                    stderr=(tmp_path / f"{u.name}.err").open("w"),
                )
            )
        owner = stack.enter_context(
            managed_process(
                _node(
                    "line_owner",
                    "-r",
                    "__ns:=/line",
                    "-p",
                    "line:=two_units",
                    "-p",
                    "parcels:=10",
                    "-p",
                    "seed:=3",
                    "-p",
                    "warm_up:=false",
                    "-p",
                    f"summary:={out}",
                    *beat,
                ),  # fmt: skip
                env,
            )
        )
        wait_until(lambda: owner.poll() is not None, 900, "the line owner's end",
                   poll=lambda: executor.spin_once(timeout_sec=0.1))  # fmt: skip
        _, err = owner.communicate()
        units = "".join((tmp_path / f"{u.name}.err").read_text()[-1500:] for u in TWO.units)
        assert owner.returncode == 0, err[-2000:] + units
        got = json.loads(out.read_text())
        # the units run on: their heartbeats reach the final counts
        for u in TWO.units:
            fig = got["units"][u.name]
            want = {
                "handoffs_arrived": str(fig["handoffs_in"]),
                "handoffs_received": str(fig["handoffs_in"]),
                "handoffs_sent": str(fig["handoffs_out"]),
                "handoffs_published": str(fig["handoffs_out"]),
                "handoffs_refused": "0",
                "handoffs_lost": "0",
                "bad_messages": "0",
            }

            def final(name=u.name, want=want):
                v = _beat(received, f"/{name}/line_unit")
                return v is not None and {k: v.get(k) for k in want} == want

            wait_until(final, 60, f"{u.name}'s heartbeat with the final counts",
                       poll=lambda: executor.spin_once(timeout_sec=0.1))  # fmt: skip
    diff = {k: (ref[k], got.get(k)) for k in ref if k not in WALL and ref[k] != got.get(k)}
    assert diff == {}
    assert got["drained"] and got["conservation_ok"] and got["handoffs_balanced"]
    for link, v in got["links"].items():
        assert v["sent"] == v["received"] > 0, link
        assert v["lost"] == 0 and sum(v["refused"].values()) == 0, link
