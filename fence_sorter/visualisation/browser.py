"""A Rerun recording in Rerun's own web viewer (bundled in rerun-sdk) under headless Chromium.

:class:`WebViewer` serves the .rrd over HTTP on 127.0.0.1 (a file server thread of ours) and
the web viewer's page with ``rerun --web-viewer`` (127.0.0.1, an HTTP URL given: no gRPC
server); :func:`shoot` drives Debian's ``chromium`` with playwright-core (the Node project in
``test/js/browser/``, installed by ``scripts/bootstrap.sh``) and writes one PNG per
:class:`Shot`. Requests to any other host (the viewer's web fonts, usage analytics and release
check) are refused in the browser and reported apart, so nothing leaves the machine and their
failures are not taken for viewer errors.

The viewer draws into one canvas (egui) with no DOM to query: a shot's actions are key presses
and clicks at positions of the fixed window size (:data:`WIDTH` x :data:`HEIGHT`), and the
screenshots are the evidence.
"""

from __future__ import annotations

import functools
import http.server
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fence_sorter.resources import checkout_root

WIDTH, HEIGHT = 1280, 800
#: the time panel's time bar at this window size (first and last instant of the recording) [px]
TIME_BAR = (292.0, 1073.0, 786.0)
#: the tabs of the default blueprint at this window size [px]
TAB_TOP = (45, 50)
TAB_3D = (305, 50)  # right of the top view tab and its long name
TAB_SERIES = (820, 50)
TAB_DAMAGE = (921, 50)
#: console errors that follow from the refused outside requests (and nothing else)
BLOCKED_ERRORS = ("net::ERR_BLOCKED_BY_CLIENT", "TypeError: Failed to fetch")


def node_project() -> Path | None:
    """The Node project (playwright-core) that drives the browser (in a source checkout)."""
    root = checkout_root()
    return root / "test" / "js" / "browser" if root is not None else None


def find_chromium() -> str | None:
    """Debian's chromium (``FENCE_SORTER_CHROMIUM`` overrides), or None."""
    env = os.environ.get("FENCE_SORTER_CHROMIUM")
    if env:
        return env if Path(env).is_file() else None
    return shutil.which("chromium") or shutil.which("chromium-browser")


def missing_tools() -> str | None:
    """Why the browser cannot be driven here (one line), or None."""
    if find_chromium() is None:
        return "no chromium (Debian's package; scripts/bootstrap.sh installs it)"
    if shutil.which("node") is None:
        return "no node (Node.js) on PATH"
    project = node_project()
    if project is None:
        return "no source checkout: the browser driver lives in test/js/browser/"
    if not (project / "node_modules" / "playwright-core").is_dir():
        return f"no playwright-core in {node_project()} (scripts/bootstrap.sh, step npm)"
    return None


@dataclass
class Shot:
    """One screenshot: ``time`` [s] to put the time cursor at (None: leave it), after clicks
    at ``tabs`` (e.g. :data:`TAB_3D`). Shots are taken in order on one page: a tab stays
    chosen for the next shots."""

    name: str
    time: float | None = None
    tabs: tuple[tuple[int, int], ...] = ()
    result: dict = field(default_factory=dict)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _Files(http.server.SimpleHTTPRequestHandler):
    def end_headers(self) -> None:
        self.send_header("Access-Control-Allow-Origin", "*")  # the viewer's page is another port
        super().end_headers()

    def log_message(self, format, *args) -> None:  # noqa: A002 - the base class's name
        pass


class WebViewer:
    """Serves ``rrd`` and Rerun's web viewer on 127.0.0.1 while the ``with`` block runs."""

    def __init__(self, rrd: Path, timeout: float = 60.0) -> None:
        self.rrd = Path(rrd).resolve()
        self.timeout = timeout

    def __enter__(self) -> WebViewer:
        self._dir = tempfile.TemporaryDirectory(prefix="fence_sorter_views_")
        (Path(self._dir.name) / "recording.rrd").symlink_to(self.rrd)
        handler = functools.partial(_Files, directory=self._dir.name)
        self._files = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        threading.Thread(target=self._files.serve_forever, daemon=True).start()
        self.rrd_url = f"http://127.0.0.1:{self._files.server_port}/recording.rrd"
        web_port = _free_port()
        env = dict(os.environ, RERUN_ANALYTICS_ENABLED="false")
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "rerun", "--web-viewer", "--bind", "127.0.0.1",
             "--port", str(_free_port()), "--web-viewer-port", str(web_port), self.rrd_url],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, start_new_session=True,
        )  # fmt: skip
        self.page = f"http://127.0.0.1:{web_port}/?url={urllib.parse.quote(self.rrd_url, '')}"
        deadline = time.monotonic() + self.timeout
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=2):
                    break
            except OSError:
                if self._proc.poll() is not None or time.monotonic() > deadline:
                    err = self._proc.stderr.read().decode(errors="replace")[-500:]
                    self.__exit__(None, None, None)
                    raise RuntimeError(f"rerun --web-viewer did not serve: {err}") from None
                time.sleep(0.2)
        return self

    def __exit__(self, *exc) -> None:
        if self._proc.poll() is None:
            os.killpg(self._proc.pid, signal.SIGTERM)  # rerun's binary is a child of python
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self._proc.pid, signal.SIGKILL)
                self._proc.wait()
        self._files.shutdown()
        self._files.server_close()
        self._dir.cleanup()


def _actions(shot: Shot, t_range: tuple[float, float]) -> list[dict]:
    """The tabs, then the time cursor: a click on the time bar at the shot's time (the bar
    spans the recording's time range)."""
    # clicks 0.8 s apart: two quicker ones are a double click to egui
    acts: list[dict] = [{"wait_ms": 800, "click": [x, y]} for x, y in shot.tabs]
    if shot.tabs:
        acts.append({"key": "Escape"})  # the clicked tab is selected (highlit): clear it
    if shot.time is not None:
        lo, hi = t_range
        x0, x1, y = TIME_BAR
        f = min(max((shot.time - lo) / (hi - lo), 0.0), 1.0) if hi > lo else 0.0
        acts.append({"wait_ms": 800, "click": [round(x0 + f * (x1 - x0)), y]})
    return acts


def shoot(
    viewer: WebViewer,
    shots: list[Shot],
    out_dir: Path,
    t_range: tuple[float, float],
    timeout: float = 240.0,
) -> list[Shot]:
    """Screenshots of ``shots`` into ``out_dir/<name>.png``; each shot's ``result`` holds what
    the browser reported (settled, console and page errors, refused outside requests)."""
    cfg = {
        "chromium": find_chromium(),
        "width": WIDTH,
        "height": HEIGHT,
        "timeout_ms": int(timeout * 1000),
        "settle_ms": 1500,
        "url": viewer.page,
        "files": ["recording.rrd"],
        "shots": [
            {
                "name": s.name,
                "png": str(Path(out_dir) / f"{s.name}.png"),
                "actions": _actions(s, t_range),
            }
            for s in shots
        ],
    }
    proc = subprocess.run(
        ["node", str(node_project() / "shoot.mjs"), json.dumps(cfg)],
        capture_output=True, text=True, timeout=timeout * (len(shots) + 2),
    )  # fmt: skip
    by_name = {}
    for line in proc.stdout.splitlines():
        if line.startswith("{"):
            d = json.loads(line)
            by_name[d["name"]] = d
    if proc.returncode != 0 or len(by_name) != len(shots):
        raise RuntimeError(f"browser failed: {proc.stderr.strip()[-800:]}")
    for s in shots:
        s.result = by_name[s.name]
        blocked = bool(s.result["external_requests"])
        s.result["viewer_errors"] = [
            e
            for e in s.result["console_errors"]
            if not (blocked and any(b in e for b in BLOCKED_ERRORS))
        ] + s.result["page_errors"]
    return shots


def time_range(rrd: Path, timeline: str = "sim_time") -> tuple[float, float]:
    """First and last instant [s] of ``timeline`` in the recording."""
    from rerun.chunk import RrdReader  # lazy: Rerun (0.5 s), only to read a recording

    lo, hi = np.inf, -np.inf
    for chunk in RrdReader(Path(rrd)).stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if timeline in batch.schema.names:
            ns = batch.column(timeline).cast("int64").to_numpy(zero_copy_only=False)
            lo, hi = min(lo, int(ns.min())), max(hi, int(ns.max()))
    if not np.isfinite(lo):
        raise ValueError(f"{rrd}: no data on the timeline {timeline}")
    return lo * 1e-9, hi * 1e-9


def is_line_recording(rrd: Path) -> bool:
    """A line's recording (``fence-sorter line-sim --rrd``: units under ``top/units``)."""
    from rerun.chunk import RrdReader  # lazy: Rerun (0.5 s), only to read a recording

    return any(
        chunk.entity_path.startswith("/top/units/") for chunk in RrdReader(Path(rrd)).stream()
    )
