"""`fence-sorter topic list|echo|hz` against a real publisher in another process over DDS."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from processes import managed_process

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TOPIC = "/test_joint"
PERIOD = 0.02  # the header stamps' spacing [s]: 50 Hz in stamp time, whatever the wall rate

PUBLISHER = f"""
import rclpy
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import JointState

rclpy.init()
node = rclpy.create_node("test_joint_publisher")
pub = node.create_publisher(JointState, "{TOPIC}", 10)
k = [0]

def tick():
    msg = JointState(name=["fence_drive"], position=[0.1 * k[0]])
    ns = round(k[0] * {PERIOD} * 1e9)
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
    pub.publish(msg)
    k[0] += 1

node.create_timer(0.01, tick)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
"""


@pytest.fixture
def publisher(env, tmp_path: Path):
    script = tmp_path / "publisher.py"
    script.write_text(PUBLISHER)
    with managed_process([sys.executable, str(script)], env) as proc:
        yield proc


def topic_cli(env, domain_id: int, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", "topic", *args, "--domain",
         str(domain_id), "--timeout", "60"],
        capture_output=True, text=True, timeout=120, env=env,
    )  # fmt: skip


def test_echo_prints_the_published_messages(publisher, env, domain_id):
    out = topic_cli(env, domain_id, "echo", TOPIC, "-n", "5", "--json")
    assert out.returncode == 0, out.stderr
    msgs = [json.loads(line) for line in out.stdout.splitlines()]
    assert len(msgs) == 5
    ks = []
    for m in msgs:
        assert m["name"] == ["fence_drive"]
        t = m["header"]["stamp"]["sec"] + 1e-9 * m["header"]["stamp"]["nanosec"]
        k = round(t / PERIOD)
        assert m["position"][0] == pytest.approx(0.1 * k, abs=1e-12)
        ks.append(k)
    assert ks == list(range(ks[0], ks[0] + 5))  # reliable: consecutive, none lost


def test_echo_yaml_and_list_show_the_topic(publisher, env, domain_id):
    out = topic_cli(env, domain_id, "echo", TOPIC, "-n", "1")
    assert out.returncode == 0, out.stderr
    assert out.stdout.rstrip().endswith("---")
    assert "- fence_drive" in out.stdout
    listed = topic_cli(env, domain_id, "list", "-t", "--wait", "60")
    assert listed.returncode == 0, listed.stderr
    assert f"{TOPIC} [sensor_msgs/msg/JointState]" in listed.stdout.splitlines()


def test_hz_reports_the_stamp_rate(publisher, env, domain_id):
    out = topic_cli(env, domain_id, "hz", TOPIC, "-n", "30", "--json")
    assert out.returncode == 0, out.stderr
    figures = json.loads(out.stdout.splitlines()[-1])
    stamps, wall = figures["stamps"], figures["wall"]
    assert stamps["window"] == wall["window"] == 29
    # consecutive stamps 0.02 s apart: 50 Hz, every interval the same
    assert stamps["rate"] == pytest.approx(1.0 / PERIOD, rel=1e-6)
    assert stamps["min"] == pytest.approx(PERIOD, abs=1e-9)
    assert stamps["max"] == pytest.approx(PERIOD, abs=1e-9)
    assert wall["min"] <= 1.0 / wall["rate"] <= wall["max"]


def test_missing_topic_and_bad_domain(env, domain_id):
    out = topic_cli(env, domain_id, "echo", "/nobody_publishes_this", "-n", "1", "--timeout")
    assert out.returncode == 2  # --timeout without a value (argparse)
    out = subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", "topic", "hz", "/nobody", "--domain",
         "300"],
        capture_output=True, text=True, timeout=60, env=env,
    )  # fmt: skip
    assert out.returncode == 2
    assert "--domain must be in 0..232" in out.stderr
    out = subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", "topic", "echo", "/nobody", "--domain",
         str(domain_id), "--timeout", "1"],
        capture_output=True, text=True, timeout=60, env=env,
    )  # fmt: skip
    assert out.returncode == 1
    assert "no publisher on the graph within 1 s" in out.stderr


def test_byte_fields_print_as_integers():
    """rclpy gives byte fields (DiagnosticStatus.level) as bytes, which JSON cannot hold."""
    from fence_sorter.cli.topic import plain

    assert plain({"level": b"\x02", "raw": [b"\x01\x02"], "x": 1.5}) == {
        "level": 2,
        "raw": [[1, 2]],
        "x": 1.5,
    }
