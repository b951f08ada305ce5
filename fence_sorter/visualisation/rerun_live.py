"""Live Rerun logging for a real-time loop, in a child process (no ROS).

Rerun's Python logging costs about 1 ms of interpreter time per frame; in the simulator's
process that time (and the GIL it holds) would land on the 1 kHz pacing loop. So the loop only
packs each published snapshot into a few hundred bytes (:func:`pack_snapshot`, ~20 us) and
writes it to a pipe without ever blocking (:class:`RerunProcess`: a frame that does not fit the
pipe's buffer is dropped and counted); a child process (``python -m
fence_sorter.visualisation.rerun_live``) unpacks the frames and logs them with
:class:`~fence_sorter.visualisation.rerun_log.RerunLogger` into an .rrd and/or a viewer.

The child ignores SIGINT/SIGTERM (the run stops the whole process group) and ends when the pipe
closes, after flushing the recording: the parent closes it in :meth:`RerunProcess.close`, or the
kernel does when the parent dies.
"""

from __future__ import annotations

import argparse
import errno
import fcntl
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fence_sorter.visualisation.frames import FenceFrame, ParcelFrame, SceneGeometry
from fence_sorter.visualisation.rerun_keys import outcome_of_line
from fence_sorter.visualisation.rerun_layout import TIMELINE, open_recording
from fence_sorter.visualisation.rerun_log import RerunLogger

KIND_FRAME, KIND_EVENT, KIND_SORT_EVENT = 1, 2, 3
_HEAD = struct.Struct("<IB")  # payload length, kind
_FRAME = struct.Struct("<dddII")  # t, alpha, tip deflection, nodes, parcels
PARCEL_COLUMNS = 17
MAX_BUFFER = 1 << 20  # bytes held back when the pipe is full before frames are dropped
NICE = 19  # niceness of the child


def pack_snapshot(snap) -> bytes:
    """A :class:`fence_sorter.line.LineSnapshot` as one message for the child."""
    f = snap.fence
    nx = np.asarray(f.node_x, dtype=np.float64)
    ny = np.asarray(f.node_y, dtype=np.float64)
    rows = np.empty((len(snap.parcels), PARCEL_COLUMNS))
    for i, p in enumerate(snap.parcels):
        corners = p.corners
        n = len(corners)
        cx = sum(c[0] for c in corners) / n if n else p.x
        cy = sum(c[1] for c in corners) / n if n else p.y
        rows[i] = (
            p.parcel_id, p.x, p.y, p.yaw, p.vx, p.vy, cx, cy, p.length_a, p.width_b, p.height,
            p.contact_normal_force, p.contact_normal_force_stiff, p.contact_point[0],
            p.contact_point[1], float(p.divert), float(p.stage),
        )  # fmt: skip
    payload = (
        _FRAME.pack(snap.t, f.drive_angle, f.tip_deflection, nx.size, rows.shape[0])
        + nx.tobytes()
        + ny.tobytes()
        + rows.tobytes()
    )
    return _HEAD.pack(len(payload), KIND_FRAME) + payload


def pack_event(t: float, text: str, ok: bool) -> bytes:
    payload = struct.pack("<d?", t, ok) + text.encode("utf-8")
    return _HEAD.pack(len(payload), KIND_EVENT) + payload


def pack_sort_event(ev, risk: dict | None) -> bytes:
    """A :class:`fence_sorter.analysis.events.SortEventData` and its damage risk for the child
    (pickled: a few hundred kB at most, once per stroke, in the node's process)."""
    payload = pickle.dumps((ev, risk), protocol=pickle.HIGHEST_PROTOCOL)
    return _HEAD.pack(len(payload), KIND_SORT_EVENT) + payload


def unpack_frame(payload: bytes) -> tuple[float, FenceFrame, list[ParcelFrame]]:
    t, alpha, tip, n_nodes, n_parcels = _FRAME.unpack_from(payload)
    off = _FRAME.size
    nx = np.frombuffer(payload, np.float64, n_nodes, off)
    ny = np.frombuffer(payload, np.float64, n_nodes, off + 8 * n_nodes)
    rows = np.frombuffer(payload, np.float64, n_parcels * PARCEL_COLUMNS, off + 16 * n_nodes)
    rows = rows.reshape(n_parcels, PARCEL_COLUMNS)
    parcels = [
        ParcelFrame(int(r[0]), *(float(v) for v in r[1:15]), divert=bool(r[15]), stage=int(r[16]))
        for r in rows
    ]
    return t, FenceFrame(alpha, nx, ny, tip), parcels


class RerunProcess:
    """Parent side: start the child, hand it frames without blocking, close it."""

    def __init__(
        self,
        scene: SceneGeometry,
        path: Path | str | None = None,
        url: str | None = None,
        spawn: bool = False,
        lossless: bool = False,
    ) -> None:
        """``lossless``: wait for the child instead of dropping frames (for unpaced runs,
        where no deadline is at stake)."""
        if path is None and not url and not spawn:
            raise ValueError("RerunProcess needs an .rrd path, a viewer url or spawn")
        cmd = [sys.executable, "-m", "fence_sorter.visualisation.rerun_live",
               "--belt-width", repr(scene.belt_width),
               "--belt-x", repr(scene.belt_x[0]), repr(scene.belt_x[1])]  # fmt: skip
        if scene.chute is not None:
            cmd += ["--chute", *(repr(v) for v in scene.chute)]
        if scene.scan_line_x is not None:
            cmd += ["--scan-line-x", repr(scene.scan_line_x)]
        if path is not None:
            cmd += ["--out", str(path)]
        if url:
            cmd += ["--url", url]
        if spawn:
            cmd.append("--spawn")
        env = dict(os.environ, RERUN_ANALYTICS_ENABLED="false")
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        # wait until the child has imported Rerun and opened its sinks (a second or two of
        # CPU that must not overlap the real-time loop)
        ready = self.proc.stdout.readline()
        self.proc.stdout.close()
        if ready.strip() != b"ready":
            self.proc.kill()
            self.proc.wait()
            raise RuntimeError(f"rerun_live child did not start (exit {self.proc.returncode})")
        self._fd = self.proc.stdin.fileno()
        flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
        fcntl.fcntl(self._fd, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        self._buffer = bytearray()
        self.lossless = lossless
        self.sent = 0
        self.dropped = 0
        self.broken = False

    def offer(self, snapshot) -> None:
        """Queue one snapshot; never blocks (drops it when the child is too far behind)."""
        self._send(pack_snapshot(snapshot))

    def event(self, t: float, text: str, ok: bool = True) -> None:
        self._send(pack_event(t, text, ok))

    def sort_event(self, ev, risk: dict | None = None) -> None:
        """Queue one full-rate sorting event (logged by :meth:`RerunLogger.log_event`)."""
        self._send(pack_sort_event(ev, risk))

    def _send(self, message: bytes) -> None:
        if self.broken:
            self.dropped += 1
            return
        if self.lossless:
            while len(self._buffer) > MAX_BUFFER // 4 and not self.broken:
                select.select([], [self._fd], [], 1.0)
                self._flush()
        if len(self._buffer) + len(message) > MAX_BUFFER:
            self.dropped += 1
        else:
            self._buffer += message
            self.sent += 1
        self._flush()

    def _flush(self) -> None:
        while self._buffer:
            try:
                n = os.write(self._fd, self._buffer)
            except BlockingIOError:
                return
            except OSError as exc:  # the child is gone
                if exc.errno in (errno.EPIPE, errno.EBADF):
                    self.broken = True
                    self._buffer.clear()
                    return
                raise
            del self._buffer[:n]

    def close(self, timeout: float = 30.0) -> int | None:
        """Send what is held back, close the pipe, wait for the child to flush and exit."""
        deadline = time.monotonic() + timeout
        while self._buffer and not self.broken and time.monotonic() < deadline:
            self._flush()
            time.sleep(0.005)
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=max(deadline - time.monotonic(), 1.0))
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        return self.proc.returncode


def _read_exact(stream, n: int) -> bytes | None:
    data = stream.read(n)
    return data if data is not None and len(data) == n else None


def child_main(argv: list[str] | None = None) -> int:
    """The child: frames from stdin into Rerun until the pipe closes."""
    parser = argparse.ArgumentParser(prog="rerun_live")
    parser.add_argument("--belt-width", type=float, required=True)
    parser.add_argument("--belt-x", type=float, nargs=2, default=(-3.0, 3.0))
    parser.add_argument("--chute", type=float, nargs=4)
    parser.add_argument("--scan-line-x", type=float)
    parser.add_argument("--out")
    parser.add_argument("--url")
    parser.add_argument("--spawn", action="store_true")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when we end
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        os.nice(NICE)  # the real-time loop's process goes first when the CPUs are busy
    except OSError:
        pass

    scene = SceneGeometry(
        args.belt_width,
        tuple(args.belt_x),
        tuple(args.chute) if args.chute else None,
        args.scan_line_x,
    )
    rec = open_recording(args.out, spawn=args.spawn, url=args.url, scene=scene)
    # a viewer: the scene in batches of 5 frames (0.1 s at 50 Hz); a file alone: 25
    logger = RerunLogger(rec, scene, scene_every=5 if args.spawn or args.url else 25)
    rr = logger.rr
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    stream = sys.stdin.buffer
    while True:
        head = _read_exact(stream, _HEAD.size)
        if head is None:
            break
        size, kind = _HEAD.unpack(head)
        payload = _read_exact(stream, size)
        if payload is None:
            break
        if kind == KIND_FRAME:
            logger.log_frame(*unpack_frame(payload))
        elif kind == KIND_EVENT:
            t, ok = struct.unpack_from("<d?", payload)
            rec.set_time(TIMELINE, duration=t)
            text = payload[9:].decode("utf-8", "replace")
            rec.log("events/outcomes", rr.TextLog(text, level="INFO" if ok else "WARN"))
            outcome = outcome_of_line(text)
            if outcome is not None:  # its mark where the parcel was last seen
                logger.log_outcome(t, *outcome)
        elif kind == KIND_SORT_EVENT:
            logger.log_event(*pickle.loads(payload))
    logger.close()
    print(f"[rerun_live] {logger.frames} frames logged", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(child_main())
