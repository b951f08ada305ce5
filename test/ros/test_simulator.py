"""The simulator executable as a separate process over DDS: parcels and commands in, clock,
states, outcomes and diagnostics out; malformed parcels counted while it keeps running.

Line: impact_flexible (belt 1 m/s, flexible fence); the test places parcels relative to the
simulator's clock so every outcome comes within a few seconds of sim time at rtf 1.
"""

from __future__ import annotations

import math
import os
import signal
from pathlib import Path

import pytest
from processes import managed_process, wait_until

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TIMEOUT = 40.0


@pytest.fixture
def probe(domain_id: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A test-process rclpy node: publishers of /parcels and /fence_commands, listeners."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    from fence_sorter.nodes.qos import RELIABLE_QOS, SENSOR_QOS, STREAM_QOS
    from fence_sorter_msgs.msg import FenceCommand, FenceState, LoadState, Parcel, SortOutcome

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log_probe"))
    context = rclpy.Context()
    rclpy.init(
        context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO
    )
    node = rclpy.create_node("test_probe", context=context)
    got: dict[str, list] = {k: [] for k in ("clock", "fence", "joint", "loads", "markers")}
    got["outcomes"], got["diag"] = [], []
    node.create_subscription(Clock, "/clock", got["clock"].append, 10)
    node.create_subscription(FenceState, "/fence_state", got["fence"].append, SENSOR_QOS)
    node.create_subscription(JointState, "/joint_states", got["joint"].append, 10)
    node.create_subscription(LoadState, "/load_states", got["loads"].append, SENSOR_QOS)
    node.create_subscription(MarkerArray, "/markers", got["markers"].append, 10)
    node.create_subscription(SortOutcome, "/sort_outcomes", got["outcomes"].append, RELIABLE_QOS)
    node.create_subscription(DiagnosticArray, "/diagnostics", got["diag"].append, RELIABLE_QOS)
    pubs = (
        node.create_publisher(Parcel, "/parcels", STREAM_QOS),
        node.create_publisher(FenceCommand, "/fence_commands", STREAM_QOS),
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield executor, pubs, got
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _spin_until(executor, proc, cond, timeout: float = TIMEOUT) -> None:
    def holds() -> bool:
        assert proc.poll() is None, proc.communicate()
        return cond()

    wait_until(
        holds, timeout, "the probe's condition", lambda: executor.spin_once(timeout_sec=0.05)
    )


def _sim_diag(got) -> dict[str, str]:
    status = [s for m in got["diag"] for s in m.status if s.name == "fence_sorter/simulator"]
    return {kv.key: kv.value for kv in status[-1].values} if status else {}


def test_simulator_sorts_reports_and_survives_bad_parcels(env, tmp_path: Path, probe) -> None:
    from fence_sorter.line import ParcelSpec, StrokeCommand
    from fence_sorter.nodes import convert
    from fence_sorter_msgs.msg import SortOutcome

    executor, (pub_parcels, pub_commands), got = probe
    params = tmp_path / "sim.yaml"
    params.write_text(
        "simulator:\n  ros__parameters:\n    heartbeat_period: 0.3\n    physics_rate: 500.0\n"
        # the parcels below are "scanned" anywhere from x0 = -1.5 to 1 m
        "    scan_line_x: 0.0\n    scan_line_tolerance: 2.0\n"
        f"    cycle_trace: {tmp_path / 'cycles.npz'}\n"
    )
    cmd = ["simulator", "--ros-args", "--params-file", str(params)]
    from processes import venv_executable

    cmd[0] = venv_executable("python")
    cmd[1:1] = ["-m", "fence_sorter.nodes.simulator"]
    with managed_process(cmd, env) as proc:
        _spin_until(executor, proc, lambda: len(got["clock"]) >= 3)
        _spin_until(
            executor,
            proc,
            lambda: pub_parcels.get_subscription_count() and pub_commands.get_subscription_count(),
        )
        clocks = [convert.time_to_sec(c.clock) for c in got["clock"]]
        assert clocks == sorted(clocks) and clocks[-1] > clocks[0]
        t0 = clocks[-1]

        def parcel(pid: int, **kw) -> None:
            base = dict(length_a=0.4, width_b=0.3, mass=15.0, lateral_gap=0.25, divert=True)
            base.update(kw)
            pub_parcels.publish(
                convert.parcel_to_msg(ParcelSpec(pid, scan_time=t0, **base), "sorter")
            )

        parcel(1, scan_position_x=-0.8)  # stroke at front 0.42 m: t0 + 1.22 s
        parcel(2, scan_position_x=1.0, divert=False)  # rear passes 3 m at t0 + 2.4 s
        parcel(3, scan_position_x=0.5)  # divert, no command: front at 2 m at t0 + 1.5 s
        parcel(4, scan_position_x=-1.5)  # the controller says infeasible
        parcel(10, scan_position_x=-1.0, mass=math.nan)
        parcel(11, scan_position_x=-1.0, mass=-3.0)
        parcel(12, scan_position_x=-1.0, width_b=0.6)  # 0.25 + 0.6 m > s = 0.7 m
        parcel(1, scan_position_x=-1.0)  # the same id with another spec: a conflict
        alpha_k = math.radians(40.0)
        pub_commands.publish(
            convert.command_to_msg(StrokeCommand(1, r_s=0.42, t1=0.35, alpha_k=alpha_k), t0)
        )
        pub_commands.publish(
            convert.command_to_msg(
                StrokeCommand(4, feasible=False, reason="no stroke meets (12)"), t0
            )
        )
        pub_commands.publish(convert.command_to_msg(StrokeCommand(77, r_s=0.0), t0))

        _spin_until(executor, proc, lambda: len(got["outcomes"]) >= 4)
        executor.spin_once(timeout_sec=0.5)
        out = {o.parcel_id: o for o in got["outcomes"]}
        assert sorted(out) == [1, 2, 3, 4], [(o.parcel_id, o.reason) for o in got["outcomes"]]
        assert out[1].reason_code == SortOutcome.SORTED and out[1].sorted
        assert 500.0 < out[1].peak_normal_force < out[1].peak_normal_force_stiff
        assert out[1].exit_speed_y > 0.0 and out[1].y_max >= 0.7
        assert out[2].reason_code == SortOutcome.NOT_DIVERTED and not out[2].sorted
        assert out[3].reason_code == SortOutcome.NO_COMMAND
        assert out[4].reason_code == SortOutcome.NO_FEASIBLE_COMMAND
        assert "no stroke meets (12)" in out[4].reason
        assert convert.time_to_sec(out[2].header.stamp) == pytest.approx(t0 + 2.4, abs=0.05)

        # states: the fence swung and bent during parcel 1's stroke, parcels were on the belt
        assert max(f.drive_angle for f in got["fence"]) > 0.5 * alpha_k
        assert max(abs(f.tip_deflection) for f in got["fence"]) > 1e-3
        assert all(len(f.node_x) == 11 for f in got["fence"])
        assert got["joint"][-1].name == ["fence_drive"]
        assert {s.parcel_id for s in got["loads"]} >= {1, 2, 3, 4}
        assert all(s.header.frame_id == "sorter" for s in got["loads"])
        assert any(m.ns == "fence" for a in got["markers"] for m in a.markers)

        # malformed parcels and the unknown command are counted; the node keeps running
        _spin_until(executor, proc, lambda: _sim_diag(got).get("bad_parcels") == "3")
        d = _sim_diag(got)
        for key in ("non_finite", "mass", "wider_than_belt"):
            assert d[f"bad_parcels.{key}"] == "1", d
        # parcel 1 again with another spec: the first stays (it was sorted), the id is disputed
        assert d["parcels.conflict"] == "1" and d["parcels.disputed_ids"] == "1", d
        assert out[1].disputed and not any(out[i].disputed for i in (2, 3, 4))
        assert d["commands_rejected.unknown_parcel"] == "1"
        # one parcel in the sector of parcel 1's stroke (t0 + 1.22 to 1.92 s): parcel 4, its
        # front at -1.5 + 1.92 = 0.42 m by the end, past 0.25 m / tan(40 deg) = 0.30 m (its
        # near side in the sector); parcels 2 and 3 are past R_z = 1.2 m from the start
        assert d["swept_sector_intrusions"] == d["overlap_warnings"] == "1", d
        assert 0.5 < float(d["real_time_factor_achieved"]) < 1.5  # paced at rtf 1 (loaded CI)
        for key in ("cycle_lateness_p50_ms", "cycle_lateness_p99_ms", "cycle_lateness_p99_9_ms"):
            assert math.isfinite(float(d[key]))
        n = len(got["clock"])
        _spin_until(executor, proc, lambda: len(got["clock"]) > n + 5)

        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, stdout + stderr
    assert "Traceback" not in stdout + stderr
    assert "mass must be a finite number" in stderr + stdout  # logged with its reason
    # the cycle trace written at shutdown: the 2 ms deadline grid, wakes at or after their
    # deadlines, phases in order, and every cycle the last heartbeat counted: a row per wake,
    # and a deadline overslept by a late wake has no row of its own but is a miss
    import numpy as np

    trace = np.load(tmp_path / "cycles.npz")
    dl = trace["deadline"]
    assert len(dl) + int(d["deadline_misses"]) >= int(d["cycles"]) > 100
    assert np.all(np.diff(trace["k"]) >= 1)
    # one deadline per cycle (a late cycle skips the ones it overslept: larger steps)
    steps = np.diff(dl)
    assert np.all(steps > 2e-3 * (1 - 1e-6)) and np.mean(np.isclose(steps, 2e-3)) > 0.95
    assert np.all(trace["wake"] >= dl)
    phases = [trace[c] for c in ("wake", "advanced", "published", "collected", "end")]
    assert all(np.all(b >= a) for a, b in zip(phases, phases[1:], strict=False))
    states = (trace["flags"] & 1) > 0  # CycleTrace.STATES: every 10th cycle at 500/50 Hz
    assert abs(states.mean() - 0.1) < 0.02


def test_bad_scene_exits_2_with_one_line(env) -> None:
    from processes import venv_executable

    cmd = [
        venv_executable("python"),
        "-m",
        "fence_sorter.nodes.simulator",
        "--ros-args",
        "-p",
        "scene:=no_such_scene",
    ]
    with managed_process(cmd, env) as proc:
        stdout, stderr = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 2
    lines = [ln for ln in stderr.splitlines() if ln.startswith("simulator:")]
    assert len(lines) == 1 and "no_such_scene" in lines[0]
    assert "Traceback" not in stdout + stderr


def test_real_time_factor_can_change_at_run_time(domain_id: int) -> None:
    """``ros2 param set /simulator real_time_factor 3``: the loop paces with the new factor
    (the pacing itself is test_pacing's, on a fake clock; the achieved rate is bench-suite's);
    read-only and out-of-range values are refused. In-process node on its own context (stop()
    restores the GC)."""
    import gc

    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from fence_sorter.line.worker import Gauges
    from fence_sorter.nodes.simulator import SimulatorNode

    context = rclpy.Context()
    rclpy.init(
        args=["--ros-args", "-p", "warm_up:=false"],
        context=context,
        domain_id=domain_id,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    node = SimulatorNode(context=context)
    try:
        node.start()

        g = node.loop.gauges
        wait_until(lambda: g.value(Gauges.RTF) == 1.0, TIMEOUT, "the loop to pace at rtf 1")
        assert node.set_parameters([Parameter("real_time_factor", value=3.0)])[0].successful
        wait_until(lambda: g.value(Gauges.RTF) == 3.0, TIMEOUT, "the loop to pace at rtf 3")
        res = node.set_parameters([Parameter("real_time_factor", value=500.0)])[0]
        assert not res.successful and "real_time_factor" in res.reason
        assert not node.set_parameters([Parameter("physics_rate", value=5.0)])[0].successful
    finally:
        node.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert gc.isenabled()


def test_unpaced_sim_time_follows_the_scanners_progress(domain_id: int) -> None:
    """Unpaced (rtf 0, scan_lead 1 s): sim time waits at its start for the scanner's first
    /scan_progress, then keeps within scan_lead of it. In-process node on its own context."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from rosgraph_msgs.msg import Clock

    from fence_sorter.line.worker import Gauges
    from fence_sorter.nodes.convert import fill_clock
    from fence_sorter.nodes.qos import RELIABLE_QOS
    from fence_sorter.nodes.simulator import SimulatorNode
    from fence_sorter.recording.topics import SCAN_PROGRESS as SCAN_PROGRESS_TOPIC

    context = rclpy.Context()
    args = ["--ros-args", "-p", "warm_up:=false", "-p", "real_time_factor:=0.0"]
    args += ["-p", "scan_lead:=1.0"]
    rclpy.init(
        args=args,
        context=context,
        domain_id=domain_id,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    node = SimulatorNode(context=context)
    other = rclpy.create_node("test_scanner_stand_in", context=context)
    progress = other.create_publisher(Clock, SCAN_PROGRESS_TOPIC, RELIABLE_QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(other)
    step = node.settings.publish_every * node.period  # sim time of one unpaced cycle

    def spin() -> None:
        executor.spin_once(timeout_sec=0.02)

    def waiting_at(t: float) -> bool:
        g = node.loop.gauges
        return g.value(Gauges.WAITING) == Gauges.WAIT_NODE and g.value(Gauges.SIM_TIME) >= t

    try:
        node.start()
        wait_until(lambda: waiting_at(0.0), TIMEOUT, "the loop to wait for a report", spin)
        assert node.sim_time <= step + 1e-9  # no report yet: held at the start
        progress.publish(fill_clock(Clock(), 4.0))
        wait_until(lambda: waiting_at(5.0), TIMEOUT, "the loop to wait past 5 s", spin)
        assert node.sim_time <= 5.0 + step + 1e-9  # up to the report + scan_lead
        progress.publish(fill_clock(Clock(), 30.0))
        wait_until(lambda: node.sim_time > 20.0, TIMEOUT, "sim time past 20 s", spin)
    finally:
        executor.shutdown()
        node.stop()
        other.destroy_node()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _loop_process(pid: int) -> int:
    """The pacing loop's process among the simulator's children."""

    from fence_sorter.line.worker import PROCESS_NAME  # lazy: numba, through the line

    def find() -> int | None:
        for task in Path(f"/proc/{pid}/task").iterdir():
            for child in (task / "children").read_text().split():
                if Path(f"/proc/{child}/comm").read_text().strip() == PROCESS_NAME:
                    return int(child)
        return None

    return wait_until(find, TIMEOUT, "the loop process")


def test_a_killed_loop_process_ends_the_node_with_status_1(env, probe) -> None:
    """kill -9 of the pacing loop's process: the node says so (FATAL, diagnostics ERROR) and
    exits 1 instead of publishing a frozen clock."""
    from processes import venv_executable

    executor, _, got = probe
    cmd = [venv_executable("python"), "-m", "fence_sorter.nodes.simulator", "--ros-args"]
    cmd += ["-p", "heartbeat_period:=0.2", "-p", "warm_up:=false"]
    with managed_process(cmd, env) as proc:
        _spin_until(executor, proc, lambda: len(got["clock"]) >= 3)
        loop = _loop_process(proc.pid)
        os.kill(loop, signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 1, stdout + stderr
    assert "pacing loop process ended (exit status -9)" in stdout + stderr
    assert "Traceback" not in stdout + stderr
