"""``python -m benchmarks calibrate-bench``: the calibration's figures into
docs/reports/calibration.md.

Interval coverage over seeds (camera60, impact_flexible), the coverage over fresh noise for
given seeds' parcels, the b_p flag from 25 Hz poses and the wall time of a 50-parcel,
5-parameter calibration (benchmarks/calibrate_bench.py).
Heavy: run it niced. Exit codes: 0 done, 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from benchmarks import REPO
from fence_sorter.cli.calibrate import add_scheduler_argument
from fence_sorter.cli.simulate import error
from fence_sorter.verification.machine import git_revision


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Measure the calibration on emulated bags with known truth."
    parser.add_argument("--seeds", type=int, default=20, help="coverage seeds (default 20)")
    parser.add_argument("--parcels", type=int, default=8, help="parcels per seed (default 8)")
    parser.add_argument(
        "--fresh-noise",
        metavar="SEEDS",
        default="",
        help="comma-separated seeds whose parcels are calibrated with --draws fresh noise draws",
    )
    parser.add_argument(
        "--draws", type=int, default=100, help="noise draws per --fresh-noise seed (default 100)"
    )
    parser.add_argument(
        "--timing-parcels",
        type=int,
        default=50,
        help="parcels of the timed calibration (default 50; 0 skips it)",
    )
    parser.add_argument("--workers", type=int, default=None, help="processes (default: CPUs)")
    add_scheduler_argument(parser)
    parser.add_argument(
        "--doc",
        metavar="FILE",
        help="fill the generated section of FILE (docs/reports/calibration.md)",
    )
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON")
    parser.add_argument(
        "--from-json",
        metavar="FILE",
        help="render the figures of an earlier --json FILE (with its command and commit)",
    )
    parser.set_defaults(func=run)  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from benchmarks import (
        calibrate_bench as bench,  # lazy: loads the kernel (Numba), SciPy, rosbags
    )

    for option, value, low in (
        ("--seeds", args.seeds, 0),
        ("--parcels", args.parcels, 3),
        ("--timing-parcels", args.timing_parcels, 0),
        ("--draws", args.draws, 1),
        ("--workers", 1 if args.workers is None else args.workers, 1),
    ):
        if value < low:
            return error(f"{option} must be in [{low}, inf), got {value}")
    try:
        args.fresh_noise_seeds = [int(v) for v in args.fresh_noise.split(",") if v.strip()]
        if any(v < 0 for v in args.fresh_noise_seeds):
            raise ValueError
    except ValueError:
        return error(f"--fresh-noise must be comma-separated integers in [0, inf), "
                     f"got {args.fresh_noise!r}")  # fmt: skip
    # lazy: loads the kernel (Numba), SciPy, rosbags
    from fence_sorter.calibration.evaluate import check_scheduler
    from fence_sorter.calibration.events import CalibrationInputError

    try:
        check_scheduler(args.scheduler)
    except CalibrationInputError as exc:
        return error(str(exc))
    if args.from_json:
        try:
            report = json.loads(Path(args.from_json).read_text(encoding="utf-8"))
            command, commit = report["command"], report["commit"]
            if not {"arch", "cpus"} <= set(report["machine"]):
                raise KeyError("machine: arch, cpus")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            return error(f"--from-json {args.from_json}: not a calibrate-bench JSON ({exc})")
    else:
        report = measure(bench, args)
        commit = git_revision(REPO)
        command = "nice -n 10 python -m benchmarks calibrate-bench " + " ".join(sys.argv[2:])
        report.update(command=command.strip(), commit=commit, machine=bench.machine())
    section = bench.render(report, command.strip(), commit)
    if args.json and not args.from_json:
        Path(args.json).write_text(json.dumps(report, indent=1, default=str), encoding="utf-8")
    if args.doc:
        bench.write_doc(Path(args.doc), section)
    print(section)
    return 0


def measure(bench, args: argparse.Namespace) -> dict:
    """The figures of ``bench`` (the calibration's benchmark module): coverage over the
    seeds, the flagged case, the timing."""
    report: dict = {}
    run_kw = {"workers": args.workers, "scheduler": args.scheduler}
    if args.seeds:
        report["coverage"] = bench.coverage(
            args.seeds, args.parcels, log=lambda s: print(s, file=sys.stderr), **run_kw
        )
    if args.fresh_noise_seeds:
        report["fresh_noise"] = bench.fresh_noise(
            args.fresh_noise_seeds, args.draws, args.parcels,
            log=lambda s: print(s, file=sys.stderr), **run_kw
        )  # fmt: skip
    report["flag"] = bench.flag_case(**run_kw)
    if args.timing_parcels:
        report["timing"] = bench.timing(args.timing_parcels, **run_kw)
    return report
