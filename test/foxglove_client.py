"""Foxglove's own npm client (test/js/foxglove/client.mjs) as a process of a test: where it is,
whether it is installed, and its output read back (ROS-free)."""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import threading
from pathlib import Path

CLIENT_DIR = Path(__file__).resolve().parent / "js" / "foxglove"
CLIENT = CLIENT_DIR / "client.mjs"


def client_missing() -> str | None:
    """Why the npm client cannot run here (a skip reason), or None."""
    if shutil.which("node") is None:
        return "Node.js (node) is not installed"
    for package in ("@foxglove/ws-protocol", "@foxglove/rosmsg2-serialization", "ws"):
        if not (CLIENT_DIR / "node_modules" / package / "package.json").is_file():
            return f"{package} is not installed in {CLIENT_DIR} (scripts/bootstrap.sh, step npm)"
    return None


def client_command(
    url: str,
    out: Path,
    topics: list[str],
    timeout: float,
    stall: bool = False,
    subprotocol: str | None = None,
) -> list[str]:
    """The command line of the npm client (``subscribed TOPIC`` lines on stdout);
    ``subprotocol``: the one it offers ("client": FoxgloveClient's own constant), else
    foxglove.sdk.v1."""
    return [
        shutil.which("node") or "node",
        str(CLIENT),
        url,
        str(out),
        f"{timeout:g}",
        *(["--stall"] if stall else []),
        *([f"--subprotocol={subprotocol}"] if subprotocol else []),
        *topics,
    ]


class Client:
    """The npm client in its own process group; its stdout lines collected as they come."""

    def __init__(
        self,
        url: str,
        out: Path,
        topics: list[str],
        timeout: float,
        stall: bool = False,
        subprotocol: str | None = None,
    ) -> None:
        self.out = out
        self.lines: list[str] = []
        self.proc = subprocess.Popen(
            client_command(url, out, topics, timeout, stall, subprotocol),
            cwd=CLIENT_DIR,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def said(self, text: str) -> bool:
        """A line of its output starts with ``text``."""
        return any(line.startswith(text) for line in list(self.lines))

    def messages(self) -> list[dict]:
        return read_messages(self.out)


def read_messages(out: Path) -> list[dict]:
    """The client's decoded messages: {topic, log_time, schema, message} per line; a last line
    still being written (no newline yet) is left for the next read."""
    if not out.is_file():
        return []
    complete = out.read_text().split("\n")[:-1]
    return [json.loads(line) for line in complete if line.strip()]


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])
