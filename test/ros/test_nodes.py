"""The node executables, started as ``ros2 run fence_sorter <node>`` would start them."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest
from processes import managed_process

pytestmark = [pytest.mark.ros, pytest.mark.slow]

NODES = {
    # node: signal that ends it (both must give a clean exit)
    "simulator": signal.SIGINT,
    "scanner": signal.SIGTERM,
    "controller": signal.SIGINT,
    "recorder": signal.SIGTERM,
}
HEARTBEATS = 2
TIMEOUT = 30.0


def resolve_executable(name: str) -> Path:
    """Resolve like ``ros2 run``: package prefix from the ament index, then lib/<pkg>/<exe>."""
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix("fence_sorter")) / "lib" / "fence_sorter" / name
    assert path.is_file() and os.access(path, os.X_OK), path
    return path


@pytest.fixture
def test_node(domain_id: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """An rclpy node in the test process, on a context of its own, and its executor."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log_listener"))
    context = rclpy.Context()
    rclpy.init(
        context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO
    )
    node = rclpy.create_node("test_listener", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.fixture
def listener(test_node):
    """The test node listening on /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray

    from fence_sorter.nodes.qos import RELIABLE_QOS

    node, executor = test_node
    received: list = []
    node.create_subscription(DiagnosticArray, "/diagnostics", received.append, RELIABLE_QOS)
    return executor, received


@pytest.mark.parametrize("name", sorted(NODES))
def test_node_beats_and_exits_cleanly(
    name: str, env: dict[str, str], tmp_path: Path, listener
) -> None:
    executor, received = listener
    params = tmp_path / "params.yaml"
    params.write_text("/**:\n  ros__parameters:\n    heartbeat_period: 0.2\n")
    cmd = [str(resolve_executable(name)), "--ros-args", "--params-file", str(params)]
    with managed_process(cmd, env) as proc:
        deadline = time.monotonic() + TIMEOUT
        mine: list = []
        while len(mine) < HEARTBEATS and time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()
            executor.spin_once(timeout_sec=0.1)
            mine = [s for msg in received for s in msg.status if s.name == f"fence_sorter/{name}"]
        assert len(mine) >= HEARTBEATS, f"{name}: no heartbeat on /diagnostics"
        assert mine[0].message  # a status text ("running", "scanning", ...)
        assert {v.key: v.value for v in mine[0].values}["node"] == f"/{name}"

        proc.send_signal(NODES[name])
        out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, out + err
    assert "Traceback" not in out + err


def test_invalid_parameter_is_refused_without_traceback(env: dict[str, str]) -> None:
    cmd = [str(resolve_executable("controller")), "--ros-args", "-p", "t1_min:=2.0"]
    with managed_process(cmd, env) as proc:
        out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 1
    assert "t1_min" in err and "t1_max" in err
    assert "Traceback" not in out + err


@pytest.mark.parametrize(
    "param", ["real_time_factor:=1e6", "loop_cpu:=-5", "command_wait:=120.0", "scan_lead:=-1.0"]
)
def test_out_of_range_parameter_is_refused(env: dict[str, str], param: str) -> None:
    cmd = [str(resolve_executable("simulator")), "--ros-args", "-p", param]
    with managed_process(cmd, env) as proc:
        out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 2  # the simulator exits 2 on a bad scene or parameter
    assert param.split(":=")[0] in err and "range" in err
    assert "Traceback" not in out + err


def test_scanner_on_the_wall_clock_publishes_its_stream_in_order(
    env: dict[str, str], test_node
) -> None:
    """Without use_sim_time the scanner checks the scan line on a wall-clock timer (with sim
    time it checks on every /clock update, which the suite's tests cover): each parcel comes
    once, in order, with its scan time."""
    from fence_sorter.nodes.qos import RELIABLE_QOS
    from fence_sorter_msgs.msg import Parcel

    node, executor = test_node
    got: list = []
    node.create_subscription(Parcel, "/parcels", got.append, RELIABLE_QOS)
    cmd = [
        str(resolve_executable("scanner")),
        "--ros-args",
        "-p", "parcels:=3",
        "-p", "start_delay:=0.2",
        "-p", "start_gate:=test_listener",
        "-p", "tick_period:=0.01",
    ]  # fmt: skip
    with managed_process(cmd, env) as proc:
        deadline = time.monotonic() + TIMEOUT
        while len(got) < 3 and time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()
            executor.spin_once(timeout_sec=0.1)
        received_at = time.time()
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=TIMEOUT)
    assert [m.parcel_id for m in got] == [1, 2, 3]
    stamps = [m.scan_time.sec + 1e-9 * m.scan_time.nanosec for m in got]
    assert stamps == sorted(stamps)
    # wall-clock stamps (system time), not sim time starting at 0
    assert abs(stamps[0] - received_at) < 60.0
