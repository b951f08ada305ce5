"""``fence-sorter accuracy``: work-precision diagrams of every integration method.

For each scene and method over a range of step sizes or tolerances: the error against a
converged reference (peak contact force, trajectory, fence tip deflection, final pose) against
wall time, as PNG plots and a markdown table (``--out``/README.md) that records this command.
The library is ``fence_sorter.verification.accuracy``.

Exit codes: 0 the campaign finished (individual solves may be capped or fail; the report says
so), 2 bad arguments (unknown scene or method: one line naming it and the allowed values),
3 a reference solve failed (no report is written).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from fence_sorter.scene import available_scenes

EXIT_OK = 0
EXIT_BAD_ARGS = 2
EXIT_FAILED = 3
DEFAULT_OUT = "accuracy"


def error(message: str, code: int = EXIT_BAD_ARGS) -> int:
    print(f"fence-sorter: error: {message}", file=sys.stderr)
    return code


def register(parser: argparse.ArgumentParser) -> None:
    # lazy: loads the kernel (Numba), SciPy
    from fence_sorter.verification.accuracy import METHODS, SCENES

    parser.description = (
        "Solve benchmark scenes with every method over a range of step sizes or "
        "tolerances, compare with a converged reference and write error-against-wall-time "
        "plots and a markdown report."
    )
    parser.add_argument(
        "--scenes",
        nargs="+",
        metavar="SCENE",
        help=f"shipped scene names (default: {' '.join(SCENES)}; --quick: positioned_stiff)",
    )
    parser.add_argument(
        "--methods",
        nargs="+",
        metavar="METHOD",
        help=f"methods to run (default: all of {' '.join(METHODS)}; --quick: a subset)",
    )
    parser.add_argument(
        "--out", default=DEFAULT_OUT, help=f"output directory (default: {DEFAULT_OUT})"
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="timed runs per setting, median reported (default: 3; --quick: 1)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="reduced grid: one scene, 2-3 settings per method, fewer SciPy methods",
    )
    parser.add_argument(
        "--plots-only",
        action="store_true",
        help="redraw the diagrams and README.md in --out from its results.json, run nothing",
    )
    parser.add_argument(
        "--max-wall",
        type=float,
        default=30.0,
        metavar="SECONDS",
        help="wall-time cap of each solve; a capped solve is reported as such (default: 30)",
    )
    parser.set_defaults(func=run)


def command_line(args: argparse.Namespace, repeats: int) -> str:
    """The effective command, every option spelled out."""
    parts = ["fence-sorter", "accuracy"]
    if args.scenes:
        parts += ["--scenes", *args.scenes]
    if args.methods:
        parts += ["--methods", *args.methods]
    parts += ["--out", args.out, "--repeats", str(repeats), "--max-wall", f"{args.max_wall:g}"]
    if args.quick:
        parts.append("--quick")
    return shlex.join(parts)


def run(args: argparse.Namespace) -> int:
    from fence_sorter.verification import accuracy  # lazy: loads the kernel (Numba), SciPy

    if args.plots_only:
        results = Path(args.out) / "results.json"
        if not results.is_file():
            return error(f"--out: no {results} to plot from")
        for path in accuracy.replot(args.out):
            print(path)
        print(accuracy.rerender(args.out))
        return 0
    known = available_scenes()
    for name in args.scenes or ():
        if name not in known:
            return error(f"unknown scene {name!r}; one of {', '.join(known)}")
    for name in args.methods or ():
        if name not in accuracy.METHODS:
            return error(f"unknown method {name!r}; one of {', '.join(accuracy.METHODS)}")
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 3)
    if repeats < 1:
        return error(f"--repeats must be at least 1, got {repeats}")
    if not 0.1 <= args.max_wall <= 3600.0:
        return error(f"--max-wall must be in [0.1, 3600] s, got {args.max_wall:g}")

    def progress(line: str) -> None:
        print(line, flush=True)

    try:
        campaign = accuracy.run_campaign(
            args.scenes,
            args.methods,
            args.out,
            repeats,
            args.quick,
            max_wall=args.max_wall,
            command=command_line(args, repeats),
            progress=progress,
        )
    except RuntimeError as exc:
        return error(str(exc), EXIT_FAILED)
    print(
        f"report: {args.out}/README.md ({len(campaign.scenes)} scenes, "
        f"{campaign.duration / 60:.1f} min)"
    )
    return EXIT_OK
