"""Parameters at run time: ``fence-sorter param list|get|set`` through the nodes' parameter
services, the same checks as ``--param`` before a value is sent, the node's own checks after,
and a change of the controller's a_Ndop during a real run that the next plans honour."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from processes import managed_process, run_domain_id, wait_until

from fence_sorter.nodes.parameters import NODE_PARAMETERS

pytestmark = [pytest.mark.ros, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
CLI_TIMEOUT = 90.0


def param_cli(*args: str, domain: int, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """``fence-sorter param ARGS --domain DOMAIN`` as a separate process."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", "param", *args]
        + ["--domain", str(domain), "--timeout", f"{timeout:g}"],
        capture_output=True,
        text=True,
        timeout=CLI_TIMEOUT + timeout,
        env=env,
        stdin=subprocess.DEVNULL,
    )


@pytest.fixture
def controller(env: dict[str, str], domain_id: int, tmp_path: Path):
    """A controller node alone on the test's domain (no simulator: it listens at once)."""
    cmd = [
        sys.executable,
        "-m",
        "fence_sorter.nodes.controller",
        "--ros-args",
        "-p",
        "wait_for_command_subscribers:=0",
        "-p",
        "warmup_time:=0.5",
    ]
    with (tmp_path / "controller.log").open("w") as log:
        with managed_process(cmd, env, stdout=log, stderr=subprocess.STDOUT) as proc:
            yield proc, domain_id


def test_param_list_get_set_through_the_services(controller) -> None:
    proc, domain = controller
    listed = param_cli("list", "controller", domain=domain)
    assert listed.returncode == 0, listed.stdout + listed.stderr
    lines = dict(line.split(": ", 1) for line in listed.stdout.splitlines())
    specs = NODE_PARAMETERS["controller"]
    assert {s.name for s in specs} <= lines.keys()
    for spec in specs:  # each descriptor's read_only as the table says
        kind, when = lines[spec.name].split(", ")
        assert when == ("read-only" if spec.read_only else "settable at run time"), spec.name
    assert lines["a_ndop"] == "double, settable at run time"
    assert lines["run_id"] == "integer, read-only"
    assert lines["active_constraints"] == "integer array, settable at run time"

    got = param_cli("get", "controller", "a_ndop", domain=domain)
    assert (got.returncode, got.stdout) == (0, "a_ndop: 300.0\n"), got.stderr
    # an integer widens to a double, as with --param
    done = param_cli("set", "controller", "a_ndop", "150", domain=domain)
    assert (done.returncode, done.stdout) == (0, "a_ndop: 150.0 (set)\n"), done.stderr
    got = param_cli("get", "controller", "a_ndop", "--json", domain=domain)
    assert json.loads(got.stdout) == 150.0
    done = param_cli("set", "controller", "active_constraints", "[7, 8, 11]", domain=domain)
    assert done.returncode == 0, done.stderr
    got = param_cli("get", "controller", "active_constraints", "--json", domain=domain)
    assert json.loads(got.stdout) == [7, 8, 11]

    # outside the table's range: refused before it is sent, one line naming it
    bad = param_cli("set", "controller", "a_ndop", "2e5", domain=domain)
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr == (
        "fence-sorter param set: controller:a_ndop must be a double in [1e-06, 100000], "
        "got '2e5'\n"
    )
    # in range alone, but not with the others: the node refuses with its reason
    bad = param_cli("set", "controller", "t1_min", "1.6", domain=domain)
    assert bad.returncode == 1
    assert "refused t1_min = 1.6: controller.t1_min (1.6 s) must not exceed t1_max" in bad.stderr
    bad = param_cli("set", "controller", "run_id", "5", domain=domain)
    assert bad.returncode == 1 and "refused run_id = 5" in bad.stderr
    assert "read-only" in bad.stderr
    got = param_cli("get", "controller", "t1_min", domain=domain)
    assert got.stdout == "t1_min: 0.2\n"
    assert proc.poll() is None  # the node runs on


def test_param_of_a_node_that_is_not_there(domain_id: int) -> None:
    gone = param_cli("get", "nobody", "x", domain=domain_id, timeout=2.0)
    assert gone.returncode == 1
    assert gone.stderr.strip() == (
        "fence-sorter param get: node /nobody: no parameter services on the graph within "
        "2 s (is it running on this domain?)"
    )


#: identical parcels to divert, 4 s apart (room for the slower strokes a lower a_Ndop needs):
#: one load class, so its plans are comparable
PARCELS = 7
MANIFEST = "parcel_id,arrival_time,length_a,width_b,height,mass,lateral_gap,yaw_deg,divert\n" + (
    "".join(
        f"{i + 1},{2.0 + 4.0 * i:.1f},0.40,0.30,0.30,8.0,0.10,0.0,true\n" for i in range(PARCELS)
    )
)
#: commands planned before the change (the new limit is taken from their figures)
BEFORE = 2
#: the new a_Ndop over the smallest peak acceleration planned before it: offline, the
#: planner finds this class a slower stroke within 0.9 of it after about 20 evaluations
LIMIT_FACTOR = 0.9
#: evaluations per parcel after the change (the default 6 run out before that stroke)
BUDGET = 60


@contextmanager
def listener(domain: int):
    """An rclpy node in the test process on ``domain``, on /fence_commands and
    /parameter_events; yields what it got and a function that spins it once."""
    import rclpy
    from rcl_interfaces.msg import ParameterEvent
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_parameter_events
    from rclpy.signals import SignalHandlerOptions

    from fence_sorter.nodes.qos import topic_qos
    from fence_sorter.recording.topics import FENCE_COMMANDS
    from fence_sorter_msgs.msg import FenceCommand

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("test_param_listener", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    got: dict[str, list] = {"commands": [], "events": []}
    node.create_subscription(
        FenceCommand, FENCE_COMMANDS, got["commands"].append, topic_qos(FENCE_COMMANDS)
    )
    node.create_subscription(
        ParameterEvent, "/parameter_events", got["events"].append, qos_profile_parameter_events
    )
    try:
        yield got, lambda: executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _t(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def test_a_ndop_changed_during_a_run_holds_for_the_next_plans(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The run plans its first strokes under a_Ndop = 300 m/s^2; then `param set` raises the
    evaluation budget and lowers a_Ndop below every peak acceleration planned so far. Every
    stroke planned after the change (its header stamp after the controller's parameter
    event) is feasible with its predicted peak acceleration within the new a_Ndop, so a
    stroke other than before for the same parcels."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # restored afterwards
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log_listener"))
    domain = run_domain_id() + 1  # not the controller fixture's domain
    manifest = tmp_path / "same.csv"
    manifest.write_text(MANIFEST)
    logs = tmp_path / "logs"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--stream", str(manifest)]
    cmd += ["--rtf", "1", "--domain", str(domain), "--json", "--log-dir", str(logs)]
    with managed_process(cmd, env, stderr=subprocess.DEVNULL) as run:
        # the run refuses a domain in use: join it once its nodes are starting
        wait_until(lambda: logs.is_dir() and any(logs.glob("*.log")), 120.0, "node logs")
        with listener(domain) as (got, spin):
            wait_until(lambda: len(got["commands"]) >= BEFORE, 240.0, "the first commands", spin)
            before = list(got["commands"])
            assert all(c.feasible for c in before), [c.reason for c in before]
            limit = round(LIMIT_FACTOR * min(c.predicted_peak_accel for c in before), 3)

            def param_set(name: str, value: float, *key: str) -> tuple[int, str]:
                setter = subprocess.Popen(
                    [sys.executable, "-m", "fence_sorter.cli.main", "param", "set"]
                    + ["controller", name, f"{value}", "--domain", str(domain), *key],
                    env=env,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    text=True,
                )
                wait_until(lambda s=setter: s.poll() is not None, CLI_TIMEOUT, "param set", spin)
                out, err = setter.communicate()
                return setter.returncode, out + err

            # from outside the run (no key): refused with the reason, the plans unchanged
            code, text = param_set("w_dop", 1e-6)
            assert code == 1 and "a change in a run needs the run's key" in text, text
            for name, value in (("max_evaluations", BUDGET), ("a_ndop", limit)):
                code, text = param_set(name, value, "--key-file", str(logs / "run.key"))
                assert code == 0, text
            wait_until(lambda: run.poll() is not None, 240.0, "the end of the run", spin)
            summary = run.stdout.read()
    s = json.loads(summary)
    # the attempt from outside is named, and makes the run's exit 4; the keyed changes are
    # listed, who (the run's key), what and when (sim time)
    assert run.returncode == 4, summary
    assert s["parameter_changes_refused"]["controller"]["count"] == 1
    assert "w_dop" in s["parameter_changes_refused"]["controller"]["reasons"][0]
    changes = s["parameter_changes"]["controller"]
    assert [c.split(" ", 2)[2] for c in changes] == [
        f"max_evaluations={BUDGET}",
        f"a_ndop={limit!r}",
    ]
    assert not (logs / "run.key").exists()  # the run is over: its key is gone
    event = next(
        e
        for e in got["events"]
        if e.node == "/controller" and any(p.name == "a_ndop" for p in e.changed_parameters)
    )
    (changed,) = [p for p in event.changed_parameters if p.name == "a_ndop"]
    assert changed.value.double_value == limit
    t_change = _t(event.stamp)
    commands = got["commands"]
    planned_before = [c for c in commands if _t(c.header.stamp) < t_change]
    after = [c for c in commands if _t(c.header.stamp) > t_change]
    assert len(planned_before) >= BEFORE and len(after) >= 2, (t_change, len(commands))
    assert all(c.feasible for c in planned_before)
    for c in after:
        assert c.feasible, c.reason
        assert c.predicted_peak_accel <= limit < min(b.predicted_peak_accel for b in before)
    assert s["commands"] == PARCELS and s["infeasible_commands"] == 0
    assert s["controller"]["planner_changes"] == "2"
    assert s["by_reason"] == {"SORTED": PARCELS}, s["missed_examples"]
