"""Frames between the simulator node and its pacing loop process: pickled objects behind a
4-byte length on a pipe. The loop side keeps what it sends as objects and pickles them in a
cycle's slack (:class:`Outbox`), and reads the node's frames without blocking (:class:`Inbox`).
"""

from __future__ import annotations

import math
import os
import pickle
import select
import struct
import time
from collections import deque

#: a frame is pickled in a cycle's slack only if its kind's mean cost, times this, fits
FLUSH_COST_SAFETY = 2.0
#: ... or once it has been held back this long [s]
FLUSH_MAX_HOLD = 0.01
#: the length of a frame's pickle, before it
HEADER = struct.Struct("<I")


def frame(obj: object) -> bytes:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    return HEADER.pack(len(data)) + data


class FrameBuffer:
    """Reassembles frames from bytes read off a pipe."""

    def __init__(self) -> None:
        self.buf = bytearray()

    def feed(self, data: bytes) -> list:
        self.buf += data
        out, buf, pos = [], self.buf, 0
        while len(buf) - pos >= 4:
            (n,) = HEADER.unpack_from(buf, pos)
            if len(buf) - pos - 4 < n:
                break
            out.append(pickle.loads(buf[pos + 4 : pos + 4 + n]))
            pos += 4 + n
        if pos:
            del buf[:pos]
        return out


class Outbox:
    """Frames waiting for the pipe (loop side): kept as objects by :meth:`send` (cheap, in
    the cycle), pickled and written without blocking by :meth:`flush` (in the cycle's slack,
    as much as fits), in order."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.objects: deque = deque()
        self.buf = bytearray()
        self.cost: dict[str, float] = {}  # running mean time to pickle a frame, by kind [s]
        self.held_since = math.inf  # when the first waiting frame was first put off
        os.set_blocking(fd, False)

    def send(self, obj: tuple) -> None:
        self.objects.append(obj)

    def flush(self, until: float = math.inf, clock=time.perf_counter) -> None:
        """Pickle the frames sent, oldest first, while each one's expected cost (its kind's
        running mean, x ``FLUSH_COST_SAFETY``) ends before ``until`` on ``clock``; a frame
        held for ``FLUSH_MAX_HOLD`` goes anyway. Then write what the pipe takes now."""
        objects, cost = self.objects, self.cost
        while objects:
            kind = objects[0][0]
            now = clock()
            if now + FLUSH_COST_SAFETY * cost.get(kind, 0.0) > until:
                self.held_since = min(self.held_since, now)
                if now - self.held_since < FLUSH_MAX_HOLD:
                    break
            self.buf += frame(objects.popleft())
            spent = clock() - now
            cost[kind] = 0.9 * cost.get(kind, spent) + 0.1 * spent
            self.held_since = math.inf
        while self.buf:
            try:
                n = os.write(self.fd, self.buf)
            except BlockingIOError:
                return
            del self.buf[:n]

    def drain(self, limit: int, inbox: Inbox | None = None) -> None:
        """Block until at most ``limit`` bytes are unsent, reading ``inbox`` meanwhile (so a
        writer blocked on the other pipe cannot deadlock with this one); returns early when the
        node asks the loop to stop."""
        self.flush()
        while len(self.buf) > limit or self.objects:
            rfds = [inbox.fd] if inbox is not None else []
            r, w, _ = select.select(rfds, [self.fd], [], 1.0)
            if r:
                inbox.read()
                if inbox.stop_requested:
                    return  # the loop ends now, whatever is unsent
            if w:
                self.flush()


class Inbox:
    """Frames from the node (loop side), read without blocking."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.frames = FrameBuffer()
        self.items: list = []
        self.closed = False
        os.set_blocking(fd, False)

    def read(self) -> None:
        while not self.closed:
            try:
                data = os.read(self.fd, 1 << 16)
            except BlockingIOError:
                return
            if not data:  # the node is gone
                self.closed = True
                return
            self.items += self.frames.feed(data)

    @property
    def stop_requested(self) -> bool:
        """The node asked the loop to stop (a stop frame read, or its end of the pipe closed)."""
        return self.closed or any(item[0] == "stop" for item in self.items)

    def take(self) -> list:
        self.read()
        items, self.items = self.items, []
        return items


def read_exact(fd: int, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = os.read(fd, n - len(data))
        if not chunk:
            raise EOFError("the node closed the pipe during set-up")
        data += chunk
    return data
