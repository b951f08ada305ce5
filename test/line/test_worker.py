"""The pacing loop's own process (fence_sorter.line.worker), no ROS: frames on the pipes, the
same outcome as the line in-process, bad input counted, backpressure when unpaced, errors
reported, and a process that outlives neither a stop nor its parent."""

from __future__ import annotations

import fcntl
import math
import os
import pickle
import signal
import struct
import subprocess
import sys
import termios
import time

import pytest
from processes import process_alive, wait_until

from fence_sorter.line import LineConfig, Outcome, OutcomeCode, SortingLine
from fence_sorter.line.frames import FrameBuffer, frame
from fence_sorter.line.worker import (
    PIPE_SIZE,
    Gauges,
    LineProcess,
    LoopSettings,
    LoopStartError,
    LoopStats,
)
from fence_sorter.scene import load_scene

from .test_line import heavy, stroke

F_GETPIPE_SZ = 1032
CONFIG = LineConfig.from_scenario(load_scene("impact_flexible").scenario)
# rtf 4 at 500 Hz: a stroke's 3 s of sim in under a second of wall time
FAST = LoopSettings(period=2e-3, rtf=4.0, publish_every=10, marker_every=0, warm_up=False)


def _collect(lp: LineProcess, until, timeout: float = 60.0) -> list:
    """Frames until ``until(frames)`` holds (the loop runs on while we read)."""
    got: list = []
    end = time.monotonic() + timeout
    for item in lp.frames():
        got.append(item)
        if until(got) or time.monotonic() > end:
            break
    return got


def _outcomes(frames) -> dict[int, Outcome]:
    return {
        e.parcel_id: e for f in frames if f[0] == "events" for e in f[1] if isinstance(e, Outcome)
    }


def _last_stats(frames) -> LoopStats:
    return [f[1] for f in frames if f[0] == "stats"][-1]


def test_frames_reassemble_from_any_split():
    items = [("states", {"t": 0.5}, 1.25), ("log", "warning", "x" * 5000), ("stop",)]
    data = b"".join(frame(i) for i in items)
    for chunk in (1, 3, 4, 7, 4096, len(data)):
        buf, out = FrameBuffer(), []
        for k in range(0, len(data), chunk):
            out += buf.feed(data[k : k + chunk])
        assert out == items and not buf.buf


@pytest.mark.slow
def test_loop_process_sorts_like_the_line_in_process_and_stops_cleanly():
    # the same parcel and command on a line stepped here, in 2 ms chunks
    line = SortingLine(CONFIG)
    line.add_parcel(heavy(1))
    assert line.command(stroke(1)).accepted
    ref = {}
    for k in range(1, 2001):
        for e in line.advance(k * 2e-3):
            if isinstance(e, Outcome):
                ref[e.parcel_id] = e

    lp = LineProcess(CONFIG, None, FAST)
    try:
        t0 = lp.wait_ready(60.0)
        assert t0 == 0.0
        lp.send(("parcel", heavy(1)))
        lp.send(("command", stroke(1)))
        frames = _collect(lp, lambda got: 1 in _outcomes(got))
        assert lp.stop() == 0
        frames += list(lp.frames())  # the last frames sent before it ended
    finally:
        lp.close()
    out = _outcomes(frames)[1]
    assert out.code is OutcomeCode.SORTED
    # the same solve whatever the chunks the pacer cut the time into
    assert out.peak_normal_force == ref[1].peak_normal_force
    assert out.exit_speed_y == ref[1].exit_speed_y
    times = [f[1].t for f in frames if f[0] == "states"]
    assert times == sorted(times) and times[-1] > out.t - 0.1  # states every 80 ms of sim
    st = _last_stats(frames)  # the final counters, sent after the loop ended
    assert st.counts["parcels_received"] == 1 and st.counts["commands_accepted"] == 1
    # the running figures, in the memory shared with the loop's process
    g = lp.gauges
    assert g.value(Gauges.SIM_TIME) >= out.t and g.value(Gauges.ON_LINE) == 0
    cycles = g.value(Gauges.CYCLES)
    assert cycles > 100 and g.value(Gauges.MISSES) <= cycles
    lateness, work = g.histogram(0), g.histogram(1)
    # one sample of each per cycle run; cycles also counts the deadlines a starved loop
    # skipped, and those are misses
    assert lateness.n == work.n
    assert cycles - g.value(Gauges.MISSES) <= lateness.n <= cycles
    p99 = lateness.percentile(99.0)
    assert math.isfinite(p99) and lateness.max >= p99 - lateness.BIN
    assert lp.proc.returncode == 0


@pytest.mark.slow
def test_bad_parcel_is_counted_and_logged_and_the_loop_runs_on():
    lp = LineProcess(CONFIG, None, FAST)
    try:
        lp.wait_ready(60.0)
        lp.send(("parcel", heavy(7, mass=math.nan)))
        lp.send(("parcel", heavy(8, width_b=0.6)))  # 0.25 + 0.6 m > s = 0.7 m
        frames = _collect(
            lp, lambda got: any(f[0] == "stats" and f[1].bad_parcels for f in got[-1:])
        )
        frames += _collect(lp, lambda got: got[-1][0] == "states")  # still stepping
        assert lp.stop() == 0
    finally:
        lp.close()
    logs = [f[2] for f in frames if f[0] == "log" and f[1] == "warning"]
    assert any("parcel 7" in t and "mass" in t for t in logs), logs
    assert any("parcel 8" in t and "wider_than_belt" in t for t in logs), logs
    assert _last_stats(frames).bad_parcels == {"non_finite": 1, "wider_than_belt": 1}


@pytest.mark.slow
def test_unpaced_loop_waits_for_its_reader():
    """rtf 0: the loop runs as fast as it can until the pipe is full and UNPACED_BACKLOG
    bytes wait beyond it; then it blocks until the reader reads again."""
    lp = LineProcess(CONFIG, None, LoopSettings(period=1e-3, rtf=0.0, warm_up=False))
    try:
        lp.wait_ready(60.0)
        g = lp.gauges
        # not reading: the pipe and the loop's outbox fill up, and the loop says it waits
        in_pipe = fcntl.fcntl(lp._from_child, F_GETPIPE_SZ)
        assert PIPE_SIZE >= in_pipe >= 1 << 16
        wait_until(
            lambda: (
                g.value(Gauges.WAITING) == Gauges.WAIT_READER
                and _nread(lp._from_child) > in_pipe // 2
            ),  # full (a partly filled page ends it)
            30.0,
            "the loop to block on a full pipe",
        )
        held = g.value(Gauges.SIM_TIME)
        # reading again lets it run on: sim time moves past what was waiting
        frames = _collect(lp, lambda got: got[-1][0] == "states" and got[-1][1].t > held + 1.0)
        times = [f[1].t for f in frames if f[0] == "states"]
        assert times == sorted(times) and times[0] <= held < times[-1] - 1.0
        lp.send(("stop",))  # it sends what it holds before it ends: read on to the end
        frames = list(lp.frames())
        assert frames[-1][0] == "stats" and lp.proc.wait(timeout=10.0) == 0
    finally:
        lp.close()


def _nread(fd: int) -> int:
    return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0]


@pytest.mark.slow
def test_settings_are_checked_and_a_failing_set_up_is_reported():
    with pytest.raises(ValueError, match="period"):
        LoopSettings(period=0.0, rtf=1.0)
    with pytest.raises(ValueError, match="publish_every"):
        LoopSettings(period=1e-3, rtf=1.0, publish_every=0)
    # the warm-up needs a Scenario: the loop's process reports the error and ends
    lp = LineProcess(CONFIG, "not a scenario", LoopSettings(period=1e-3, rtf=1.0))
    try:
        with pytest.raises(LoopStartError, match="AttributeError"):
            lp.wait_ready(60.0)
        assert lp.proc.wait(timeout=10.0) == 1
    finally:
        lp.close()


@pytest.mark.slow
@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs 2 CPUs")
def test_loop_process_pins_itself_to_loop_cpu():
    cpu = max(os.sched_getaffinity(0))
    lp = LineProcess(CONFIG, None, LoopSettings(period=1e-3, rtf=1.0, loop_cpu=cpu))
    try:
        lp.wait_ready(60.0)
        frames = _collect(lp, lambda got: any(f[0] == "log" and "pinned" in f[2] for f in got))
        assert any(f[0] == "log" and f"CPU {cpu}" in f[2] for f in frames)
        assert os.sched_getaffinity(lp.proc.pid) == {cpu}
        assert lp.stop() == 0
    finally:
        lp.close()


@pytest.mark.slow
def test_loop_process_ignores_ctrl_c_and_dies_with_its_parent():
    lp = LineProcess(CONFIG, None, FAST)
    try:
        lp.wait_ready(60.0)
        cycles = lp.gauges.value(Gauges.CYCLES)
        lp.proc.send_signal(signal.SIGINT)  # Ctrl-C reaches the whole process group
        # only the node ends it, after its last frames: it steps on after the signal
        wait_until(
            lambda: lp.gauges.value(Gauges.CYCLES) > cycles + 100 or lp.proc.poll() is not None,
            30.0,
            "100 cycles after SIGINT",
        )
        assert lp.proc.poll() is None
        assert lp.stop() == 0
    finally:
        lp.close()

    code = (
        "import pickle, signal, sys\n"
        "from fence_sorter.line.worker import LineProcess\n"
        "config, settings = pickle.loads(bytes.fromhex(sys.argv[1]))\n"
        "lp = LineProcess(config, None, settings)\n"
        "lp.wait_ready(60.0)\n"
        "print(lp.proc.pid, flush=True)\n"
        "signal.pause()\n"  # until killed
    )
    arg = pickle.dumps((CONFIG, FAST)).hex()
    parent = subprocess.Popen([sys.executable, "-c", code, arg], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    os.kill(child, 0)  # running
    parent.kill()
    parent.wait()
    wait_until(lambda: not process_alive(child), 10.0, f"loop process {child} to end")


@pytest.mark.slow
def test_unpaced_lockstep_holds_a_parcel_to_divert_for_its_command():
    """rtf 0: the line does not let a parcel to divert reach the lowest R_s (r_s_min, -0.5 m
    by default) before its command came, for up to command_wait of wall time; a command that
    comes while it waits is accepted and the parcel sorted; one that never comes lets the
    line go on after command_wait (NO_COMMAND, counted)."""
    # the loop is held at t = 0 (the scanner's progress, Gauges.SCAN_LIMIT) until the parcel is
    # in its inbox: unpaced, it would otherwise run on while the parcel is on its way
    settings = LoopSettings(period=1e-3, rtf=0.0, warm_up=False, command_wait=5.0)
    lp = LineProcess(CONFIG, None, settings, scan_limit=0.0)
    try:
        lp.wait_ready(60.0)
        lp.send(("parcel", heavy(1, scan_position_x=-3.0)))  # front at -0.5 m at t = 2.5 s
        g = lp.gauges
        g.header[Gauges.SCAN_LIMIT] = math.inf
        wait_until(
            lambda: g.value(Gauges.WAITING) == Gauges.WAIT_COMMAND,
            30.0,
            "the loop to hold for the command",
        )
        assert g.value(Gauges.SIM_TIME) == pytest.approx(2.5, abs=1e-9)
        lp.send(("command", stroke(1)))  # R_s 0.42 m: the front gets there at t = 3.42 s
        frames = _collect(lp, lambda got: 1 in _outcomes(got))
        assert _outcomes(frames)[1].code is OutcomeCode.SORTED
        lp.send(("stop",))
        frames += list(lp.frames())
        assert "command_waits_given_up" not in _last_stats(frames).counts
    finally:
        lp.close()

    settings = LoopSettings(period=1e-3, rtf=0.0, warm_up=False, command_wait=0.2)
    lp = LineProcess(CONFIG, None, settings, scan_limit=0.0)
    try:
        lp.wait_ready(60.0)
        lp.send(("parcel", heavy(2, scan_position_x=-3.0)))
        lp.gauges.header[Gauges.SCAN_LIMIT] = math.inf
        frames = _collect(lp, lambda got: 2 in _outcomes(got))
        assert _outcomes(frames)[2].code is OutcomeCode.NO_COMMAND
        lp.send(("stop",))
        frames += list(lp.frames())
        assert _last_stats(frames).counts["command_waits_given_up"] == 1
    finally:
        lp.close()


@pytest.mark.slow
@pytest.mark.parametrize(
    "gauge, lead",
    [(Gauges.PUBLISHED, 0.1), (Gauges.SCAN_LIMIT, 0.0)],
    ids=["publish_lead", "scan_limit"],
)
def test_unpaced_loop_waits_for_the_node(gauge: int, lead: float):
    """rtf 0: the loop stays within publish_lead of the sim time the node has published
    (Gauges.PUBLISHED: the scanner and the controller plan on that /clock), and does not pass
    Gauges.SCAN_LIMIT (the scanner's progress plus scan_lead, written by the node)."""
    if gauge == Gauges.PUBLISHED:
        settings = LoopSettings(period=1e-3, rtf=0.0, warm_up=False, publish_lead=lead)
        lp = LineProcess(CONFIG, None, settings)
    else:
        settings = LoopSettings(period=1e-3, rtf=0.0, warm_up=False)
        lp = LineProcess(CONFIG, None, settings, scan_limit=0.0)  # held at the start
    step = settings.publish_every * settings.period  # sim time of one unpaced cycle
    try:
        lp.wait_ready(60.0)
        g = lp.gauges

        def waiting_at(t: float) -> bool:
            return g.value(Gauges.WAITING) == Gauges.WAIT_NODE and g.value(Gauges.SIM_TIME) >= t

        # the node publishes nothing, the scanner reports nothing
        wait_until(lambda: waiting_at(0.0), 30.0, "the loop to wait for the node")
        assert g.value(Gauges.SIM_TIME) <= lead + step + 1e-9
        g.header[gauge] = 5.0  # published (reported) up to 5 s
        wait_until(lambda: waiting_at(5.0), 30.0, "the loop to wait again past 5 s")
        assert g.value(Gauges.SIM_TIME) <= 5.0 + lead + step + 1e-9
        lp.send(("stop",))
        list(lp.frames())
        assert lp.proc.wait(timeout=10.0) == 0
    finally:
        lp.close()


@pytest.mark.slow
def test_no_scan_limit_unless_one_is_given():
    lp = LineProcess(CONFIG, None, LoopSettings(period=1e-3, rtf=0.0, warm_up=False))
    try:
        assert lp.gauges.value(Gauges.SCAN_LIMIT) == math.inf
    finally:
        lp.close()


@pytest.mark.slow
def test_worker_started_by_hand_with_bad_arguments_exits_2_with_usage():
    proc = subprocess.run(
        [sys.executable, "-m", "fence_sorter.line.worker", "3", "four"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "usage: python -m fence_sorter.line.worker IN_FD OUT_FD GAUGES_FD PARENT_PID" in (
        proc.stderr
    )
    assert "Traceback" not in proc.stderr
