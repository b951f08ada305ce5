"""``python -m benchmarks stability-random``: sorting events drawn at random over the space a
user reaches, each solved once, failures counted by cause with the bounds of their region.

The events and their space are :mod:`fence_sorter.verification.stability_random`'s; they run on
the evaluation pool (``--workers`` local processes). Prints the progress and the summary, and
writes ``random.json`` and ``random.md`` (rendered from the JSON) into ``--out``
(docs/reports/stability/; ``''`` writes nothing). Exits 1 if an event failed, 2 on bad
arguments.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from fence_sorter.jsonsafe import json_safe
from fence_sorter.pool import MAX_WORKERS
from fence_sorter.verification.machine import git_revision, machine_info

DEFAULT_OUT = "docs/reports/stability"
MAX_EVENTS = 10_000_000


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Random stability campaign: events drawn over the user's space (loads, belt, strokes, "
        "stiff and flexible fence), failures by cause and their region."
    )
    parser.add_argument("--events", type=int, default=10_000, metavar="N", help="default 10000")
    parser.add_argument("--seed", type=int, default=1, metavar="S", help="default 1")
    parser.add_argument("--workers", type=int, default=None, metavar="W", help="default: CPUs")
    parser.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="default %(default)s")
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"benchmarks: error: {msg}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    if not 1 <= args.events <= MAX_EVENTS:
        return _error(f"--events must be in [1, {MAX_EVENTS}], got {args.events}")
    if not 0 <= args.seed < 2**63:
        return _error(f"--seed must be in [0, 2^63), got {args.seed}")
    if args.workers is not None and not 1 <= args.workers <= MAX_WORKERS:
        return _error(f"--workers must be in [1, {MAX_WORKERS}], got {args.workers}")
    # lazy: the physics loads Numba and the compiled kernel
    from fence_sorter.verification import stability_random as R

    commit = git_revision()  # the code the events run, whatever changes meanwhile
    t0 = time.perf_counter()

    def progress(done: int, failed: int) -> None:
        if done % 1000 < 50 or done == args.events:
            rate = done / max(time.perf_counter() - t0, 1e-9)
            print(f"{done} events, {failed} failed ({rate:.0f} events/s)", flush=True)

    outcomes = R.run_campaign(args.events, args.seed, workers=args.workers, progress=progress)
    wall = time.perf_counter() - t0
    argv = ["python", "-m", "benchmarks", "stability-random", "--events", str(args.events)]
    argv += ["--seed", str(args.seed)]
    if args.workers is not None:
        argv += ["--workers", str(args.workers)]
    if args.out != DEFAULT_OUT:
        argv += ["--out", args.out]
    meta = {
        "command": shlex.join(argv),
        "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit,
        "machine": machine_info(),
        "workers": args.workers or "all CPUs",
        "wall_time_s": wall,
    }
    data = json_safe(R.results_json(outcomes, args.seed, meta))
    s = data["summary"]
    print(
        f"{s['events']} events in {wall:.1f} s: {s['solved']} solved ({s['sorted']} sorted), "
        f"{s['failures']} solver failures {s['failures_by_cause'] or ''}"
    )
    for cause, reg in s["regions"].items():
        bounds = ", ".join(f"{k} [{lo:.3g}, {hi:.3g}]" for k, (lo, hi) in reg["bounds"].items())
        print(f"  {cause}: {reg['events']} events; {bounds}; fences {reg['fences']}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "random.json").write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        (out / "random.md").write_text(R.render_markdown(data), encoding="utf-8")
        print(f"report: {out / 'random.md'}")
    return 1 if s["failures"] else 0
