"""``fence-sorter views [RRD] [--out DIR] [--mid S]``: screenshots of a Rerun recording in
Rerun's own web viewer under headless Chromium (default view, mid-run, end, 3D tab,
damage-risk tab).

Exit codes: 0 every view rendered without a viewer error; 1 a viewer error, a view that did
not settle or the browser failed; 2 a bad argument or no browser here (the line says why).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from fence_sorter.resources import checkout_root
from fence_sorter.visualisation import browser

DEFAULT_RRD = Path("bags") / "example_4_parcels.rrd"


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Render a Rerun recording in Rerun's bundled web viewer under headless Chromium "
        "(Debian's chromium, playwright-core) and write PNG screenshots: default.png (as it "
        "opens, paused), mid.png, end.png, damage.png (the damage-risk tab at the "
        "end), 3d.png (the 3D tab, mid-run); a line's recording (line-sim --rrd): the first three."
    )
    parser.add_argument(
        "rrd", nargs="?", help="the .rrd (default: the checkout's bags/example_4_parcels.rrd)"
    )
    parser.add_argument("--out", metavar="DIR", default="views", help="(default: %(default)s)")
    parser.add_argument(
        "--mid",
        type=float,
        metavar="S",
        help="sim time of the mid-run shots [s] (default: middle)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    root = checkout_root()
    rrd = Path(args.rrd) if args.rrd else (root / DEFAULT_RRD if root else DEFAULT_RRD)
    if rrd.suffix != ".rrd" or not rrd.is_file():
        print(f"fence-sorter views: error: rrd {rrd}: no such .rrd file", file=sys.stderr)
        return 2
    out = Path(args.out)
    if not out.parent.is_dir():
        print(
            f"fence-sorter views: error: --out {out}: no directory {out.parent}", file=sys.stderr
        )
        return 2
    try:
        lo, hi = browser.time_range(rrd)
    except (RuntimeError, ValueError, OSError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"fence-sorter views: error: rrd {rrd}: not a Rerun recording ({first})",
              file=sys.stderr)  # fmt: skip
        return 2
    mid = 0.5 * (lo + hi) if args.mid is None else args.mid
    if not lo <= mid <= hi:
        print(
            f"fence-sorter views: error: --mid {mid}: outside {lo:.2f}..{hi:.2f} s",
            file=sys.stderr,
        )
        return 2
    why = browser.missing_tools()
    if why:
        print(f"fence-sorter views: error: {why}", file=sys.stderr)
        return 2
    out.mkdir(exist_ok=True)
    shots = [browser.Shot("default"), browser.Shot("mid", mid), browser.Shot("end", hi)]
    if not browser.is_line_recording(rrd):  # a line's layout has no tabs
        shots += [
            # at the end: every outcome in the chart (the plots run past the end, so the
            # cursor is inside them)
            browser.Shot("damage", hi, (browser.TAB_DAMAGE,)),
            browser.Shot("3d", mid, (browser.TAB_3D, browser.TAB_SERIES)),
        ]
    try:
        with browser.WebViewer(rrd) as viewer:
            browser.shoot(viewer, shots, out, (lo, hi))
    except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:
        print(f"fence-sorter views: {exc}".splitlines()[0], file=sys.stderr)
        return 1
    status = 0
    for s in shots:
        r = s.result
        errors = r["viewer_errors"]
        when = "as before" if s.time is None else f"{s.time:.2f} s"
        print(
            f"{s.name:8s} {Path(r['png'])}  time {when}"
            f"  settled {r['settled']}  viewer errors {len(errors)}"
            f"  outside requests refused {len(r['external_requests'])}"
        )
        for e in errors:
            print(f"  error: {e.splitlines()[0]}")
        if errors or not r["settled"]:
            status = 1
    return status
