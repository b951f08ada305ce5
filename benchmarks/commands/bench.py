"""``python -m benchmarks bench``: speed and memory of the default configuration, side by side.

Runs :mod:`benchmarks.bench` (per scene: the default configuration against a
converged reference and the fastest SciPy baseline at the same error, stiff-fence event times,
peak memory, the model each scene builds against the full model, the kernel with and without
the JIT), prints the report and writes it as JSON (default ``docs/reports/benchmarks.json``) and as
markdown rendered from that JSON (default ``docs/reports/benchmarks.md``); ``--from-json`` renders
the markdown again from an earlier run's JSON without measuring anything.

Exit codes: 0 the bench ran (targets that fail are reported in the tables, not as an exit
code), 2 bad arguments (one line ``benchmarks: error: ...``; an unknown scene names the
allowed ones).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from benchmarks import bench as B
from benchmarks.bench_suite import BEGIN, END
from benchmarks.sections import section_of

EXIT_OK = 0
EXIT_BAD_ARGS = 2
DEFAULT_OUT = "docs/reports/benchmarks.md"


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Benchmark the default configuration per scene: wall time, steps, real-time "
        "factor and peak-force error against a converged reference, side by side with the "
        "fastest SciPy solve_ivp method at the same error; stiff-fence event times; peak "
        "memory; the model each scene builds against the full model; the compiled kernel "
        "against the same code with NUMBA_DISABLE_JIT=1. Prints the report and writes it "
        "as markdown."
    )
    add_arguments(parser)
    parser.set_defaults(func=run)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out",
        default=DEFAULT_OUT,
        metavar="FILE",
        help=f"markdown report to write (default {DEFAULT_OUT})",
    )
    parser.add_argument(
        "--scenes",
        nargs="+",
        metavar="NAME",
        help="shipped scenes to bench (separated by spaces or commas; default: all four)",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        metavar="N",
        help="timed calls of the default configuration per scene (default 15; --quick: 2)",
    )
    parser.add_argument(
        "--scipy-cap",
        type=float,
        default=None,
        metavar="SECONDS",
        help="wall-time cap of every SciPy run (solver.max_wall_time; default 120)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help=(
            "a fast smoke run: one scene (positioned_stiff unless --scenes), 2 repeats, "
            "2 SciPy methods, a 3-rung rtol ladder, no cold-compile measurement"
        ),
    )
    parser.add_argument(
        "--json",
        metavar="FILE",
        help="where to write every figure as JSON (default: --out with the suffix .json)",
    )
    parser.add_argument(
        "--from-json",
        metavar="FILE",
        help="measure nothing: render --out again from the JSON of an earlier run",
    )


def _error(message: str) -> int:
    print(f"benchmarks: error: {message}", file=sys.stderr)
    return EXIT_BAD_ARGS


def _suite_section(out: Path) -> str:
    """The node-suite section ``python -m benchmarks bench-suite`` keeps in the same file
    (between its markers): carried over, since this command regenerates everything else."""
    old = out.read_text(encoding="utf-8") if out.is_file() else ""
    section = section_of(old, BEGIN, END)
    return "\n" + section + "\n" if section else ""


def write_markdown(out: Path, text: str) -> None:
    """``out`` rewritten as ``text`` plus the node-suite section it held."""
    suite = _suite_section(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text + suite, encoding="utf-8")


def render_again(source: Path, out: Path) -> int:
    """``--from-json``: the markdown of an earlier run's JSON, nothing measured."""
    try:
        data = json.loads(source.read_text(encoding="utf-8"))
        text = B.render_markdown(B.report_from_dict(data))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return _error(f"--from-json {source}: not a bench report ({exc})")
    write_markdown(out, text)
    print(f"report rendered from {source} to {out}")
    return EXIT_OK


def run(args: argparse.Namespace) -> int:
    if args.from_json:
        return render_again(Path(args.from_json), Path(args.out))
    allowed = B.SCENES
    if args.scenes:
        names = [n.strip() for item in args.scenes for n in item.split(",") if n.strip()]
        unknown = [n for n in names if n not in allowed]
        if unknown:
            return _error(f"unknown bench scene {unknown[0]!r}; allowed: {', '.join(allowed)}")
        if not names:
            return _error(f"no scene given; allowed: {', '.join(allowed)}")
        scenes = list(dict.fromkeys(names))
    else:
        scenes = list(B.QUICK_SCENES if args.quick else B.SCENES)
    repeats = args.repeats if args.repeats is not None else (2 if args.quick else 15)
    if repeats < 1:
        return _error(f"--repeats must be at least 1, got {repeats}")
    cap = args.scipy_cap if args.scipy_cap is not None else B.SCIPY_CAP_S
    if not 0.1 <= cap <= 3600.0:
        return _error(f"--scipy-cap must be in [0.1, 3600] s, got {cap:g}")
    methods = B.QUICK_SCIPY_METHODS if args.quick else B.SCIPY_METHODS
    peer_methods = B.QUICK_PEER_METHODS if args.quick else B.PEER_METHODS
    ladder = B.QUICK_RTOL_LADDER if args.quick else B.RTOL_LADDER

    argv = ["python", "-m", "benchmarks", "bench"]
    if args.out != DEFAULT_OUT:
        argv += ["--out", args.out]
    if args.scenes:
        argv += ["--scenes", *scenes]
    if args.repeats is not None:
        argv += ["--repeats", str(repeats)]
    if args.scipy_cap is not None:
        argv += ["--scipy-cap", f"{cap:g}"]
    if args.quick:
        argv.append("--quick")

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    report = B.run_bench(
        scenes,
        repeats=repeats,
        methods=methods,
        ladder=ladder,
        cap=cap,
        quick=args.quick,
        command=shlex.join(argv),
        log=log,
        peer_methods=peer_methods,
    )
    out = Path(args.out)
    path = Path(args.json) if args.json else out.with_suffix(".json")
    data = json.dumps(B.report_dict(report), indent=1) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(data, encoding="utf-8")
    # the markdown is rendered from the data as written, so it can be rebuilt from the JSON
    text = B.render_markdown(B.report_from_dict(json.loads(data)))
    write_markdown(out, text)
    print(text)
    failed = [f"{t.scene}: {t.target}" for t in report.targets if t.verdict == "FAIL"]
    print(f"report written to {out}")
    if failed:
        print(f"targets not met ({len(failed)}): " + "; ".join(failed))
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m benchmarks.commands.bench``: the subcommand on its own."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks bench")
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
