"""Foxglove live: `fence-sorter run --foxglove PORT --bag DIR`, and during the run Foxglove's own
npm client (@foxglove/ws-protocol, decoding with @foxglove/rosmsg2-serialization) subscribed to
/joint_states and /sort_outcomes. Every outcome of the run reaches it, and the /joint_states
from its first message on without a gap, each message equal field by field to the one the
run's bag holds (read with rosbags); the node's /diagnostics in the bag count what it
forwarded and no slow client."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from foxglove_client import Client, client_missing, free_port
from processes import managed_process, stop_process, wait_until
from rosbags.highlevel import AnyReader

pytestmark = [
    pytest.mark.ros,
    pytest.mark.slow,
    pytest.mark.skipif(client_missing() is not None, reason=str(client_missing())),
]

REPO = Path(__file__).resolve().parents[2]
TOPICS = ["/joint_states", "/sort_outcomes"]


def _plain(value):
    """A rosbags message as the npm client's JSON has it (NaN and inf: null)."""
    if dataclasses.is_dataclass(value):
        return {
            f.name: _plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if not f.name.startswith("__") and not f.name.isupper()  # constants
        }
    if hasattr(value, "tolist"):
        return _plain(value.tolist())
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 2**53:
        return str(value)  # uint64/int64: decimal strings in the client's JSON
    return value


def _bag(path: Path) -> dict[str, list]:
    return _bag_topics(path, ["/joint_states", "/sort_outcomes", "/diagnostics"])


def _bag_topics(path: Path, topics: list[str]) -> dict[str, list]:
    """The messages of ``topics`` in the bag (rosbags), in log-time order."""
    out: dict[str, list] = {t: [] for t in topics}
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic in out]
        for conn, _t, raw in reader.messages(connections=conns):
            out[conn.topic].append(reader.deserialize(raw, conn.msgtype))
    return out


def _listening(port: int) -> list[str]:
    """The local addresses of the TCP sockets listening on ``port`` (``ss -ltn``)."""
    out = subprocess.run(["ss", "-ltnH"], capture_output=True, text=True, check=True).stdout
    return sorted(
        f.split()[3] for f in out.splitlines() if f.split()[3].rsplit(":", 1)[-1] == str(port)
    )


def _run_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return env


def _stamp(d: dict) -> tuple[int, int]:
    s = d["header"]["stamp"]
    return int(s["sec"]), int(s["nanosec"])


def test_npm_client_gets_the_runs_joint_states_and_outcomes(tmp_path: Path) -> None:
    port = free_port()
    bag = tmp_path / "bag"
    env = _run_env()
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "run", "--parcels", "4"]
    cmd += ["--bag", str(bag), "--foxglove", f"127.0.0.1:{port}", "--json"]
    cmd += ["--log-dir", str(tmp_path / "logs")]
    out = tmp_path / "client.jsonl"
    with managed_process(cmd, env, cwd=REPO) as run:
        client = Client(f"ws://127.0.0.1:{port}", out, TOPICS, timeout=240)
        try:
            wait_until(
                lambda: all(client.said(f"subscribed {t}") for t in TOPICS) or run.poll(),
                240, "the npm client's subscriptions",
            )  # fmt: skip
            listening = _listening(port)
            stdout, stderr = run.communicate(timeout=300)
            assert run.returncode == 0, stdout + stderr
            # the node stops with the run: the server closes the connection
            wait_until(lambda: client.proc.poll() is not None, 30, "the client's end")
        except subprocess.TimeoutExpired:
            pytest.fail("the run did not end within 300 s")
        finally:
            stop_process(client.proc)
    # the server's socket: on loopback only, as --foxglove 127.0.0.1:PORT asked
    assert listening == [f"127.0.0.1:{port}"], listening
    summary = json.loads(stdout)
    assert summary["exit_codes"].get("foxglove") == 0, summary["exit_codes"]
    assert client.said("closed"), client.lines
    got = client.messages()
    recorded = _bag(bag)

    # every outcome of the run, equal to the bag's
    outcomes = [m for m in got if m["topic"] == "/sort_outcomes"]
    assert len(recorded["/sort_outcomes"]) == 4
    expected = [_plain(m) for m in recorded["/sort_outcomes"]]
    for m, want in zip(outcomes, expected, strict=True):
        diff = {k: (m["message"].get(k), v) for k, v in want.items() if m["message"].get(k) != v}
        assert not diff, diff
    assert all(m["schema"] == "fence_sorter_msgs/msg/SortOutcome" for m in outcomes)

    # /joint_states: from the client's first message to the end of the run, no message missing
    states = [m["message"] for m in got if m["topic"] == "/joint_states"]
    in_bag = [_plain(m) for m in recorded["/joint_states"]]
    assert len(states) > 100, len(states)
    # the recorder and the Foxglove node each match the simulator at their own moment: from
    # the later of the two first messages on, the client has every message the bag has
    start = max(_stamp(states[0]), _stamp(in_bag[0]))
    states_from = [m for m in states if _stamp(m) >= start]
    bag_from = [m for m in in_bag if _stamp(m) >= start]
    assert len(states_from) > 100, len(states_from)
    assert states_from == bag_from  # none lost, in order, nothing lost at the end either
    # it was there before the first outcome: the run's whole stream was served
    assert _stamp(states[0]) < _stamp(outcomes[0]["message"])

    # the node's own count, on /diagnostics (its last heartbeat recorded)
    last = None
    for array in recorded["/diagnostics"]:
        for status in array.status:
            if status.name == "fence_sorter/foxglove":
                last = {kv.key: kv.value for kv in status.values}
    assert last is not None, "no heartbeat of the Foxglove node in the bag"
    assert last["forwarded.sort_outcomes"] == "4" and last["slow_clients"] == "0"
    assert last["address"] == f"127.0.0.1:{port}" and last["clients"] == "1"


def test_replay_serves_the_bag_to_the_npm_client(tmp_path: Path, env: dict[str, str]) -> None:
    """``fence-sorter replay BAG --foxglove PORT --wait S``: the replay starts once the npm
    client subscribes; the outcomes and the robot description it gets equal the bag's, and
    /joint_states from its first message on to the bag's end, without a gap."""
    port = free_port()
    bag = REPO / "bags" / "example_4_parcels"
    topics = ["/joint_states", "/sort_outcomes", "/robot_description"]
    cmd = [sys.executable, "-m", "fence_sorter.cli.main", "replay", str(bag), "--rate", "4"]
    cmd += ["--foxglove", str(port), "--wait", "120"]
    out = tmp_path / "client.jsonl"
    with managed_process(cmd, {**env, "PYTHONPATH": _run_env()["PYTHONPATH"]}, cwd=REPO) as rep:
        client = Client(f"ws://127.0.0.1:{port}", out, topics, timeout=120)
        try:
            stdout, stderr = rep.communicate(timeout=240)
            assert rep.returncode == 0, stdout + stderr
            wait_until(lambda: client.proc.poll() is not None, 30, "the client's end")
        finally:
            stop_process(client.proc)
    assert f"serving the bag to Foxglove on ws://127.0.0.1:{port}" in stdout
    got = client.messages()
    recorded = _bag_topics(bag, topics)
    for topic in ("/sort_outcomes", "/robot_description"):
        mine = [m["message"] for m in got if m["topic"] == topic]
        assert mine == [_plain(m) for m in recorded[topic]], topic
    states = [m["message"] for m in got if m["topic"] == "/joint_states"]
    in_bag = [_plain(m) for m in recorded["/joint_states"]]
    first = next(k for k, m in enumerate(in_bag) if _stamp(m) == _stamp(states[0]))
    assert states == in_bag[first:] and len(states) > 0.9 * len(in_bag)
