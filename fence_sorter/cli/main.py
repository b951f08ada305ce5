"""``fence-sorter``: the user command line.

Each subcommand lives in its own module ``fence_sorter/cli/<module>.py`` that exposes
``register(subparsers)``; ``register`` adds the subcommand's parser and sets ``func`` (called
with the parsed arguments, returns the exit code). To add a subcommand, write its module and
append the module name to :data:`SUBCOMMAND_MODULES`.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Callable, Sequence

from fence_sorter import __version__

#: Modules under fence_sorter.cli that provide subcommands, in the order of ``--help``.
SUBCOMMAND_MODULES: tuple[str, ...] = (
    "check",
    "demo_roundtrip",
    "simulate",
    "modes",
    "accuracy",
    "stability",
    "bench",
    "run",
    "replay",
    "analyze",
    "bag",
    "topic",
    "rrd",
    "bench_suite",
    "optimize",
    "faults",
    "emulate",
    "calibrate",
    "validate",
    "calibrate_bench",
)


def _unavailable(module: str, error: BaseException) -> Callable[[argparse.Namespace], int]:
    """Return a func that reports why the subcommand from ``module`` cannot be loaded."""

    def func(args: argparse.Namespace) -> int:
        del args
        print(
            f"fence-sorter: subcommand module fence_sorter.cli.{module} cannot be loaded: "
            f"{type(error).__name__}: {error}",
            file=sys.stderr,
        )
        return 1

    return func


def build_parser() -> argparse.ArgumentParser:
    """Return the top-level parser with every subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="fence-sorter",
        description="Digital twin of a rotary active fence parcel sorter.",
    )
    parser.add_argument("--version", action="version", version=f"fence-sorter {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(f"fence_sorter.cli.{module_name}")
            module.register(subparsers)
        except Exception as exc:  # a broken subcommand must not take the others down
            stub = subparsers.add_parser(
                module_name.replace("_", "-"), help=f"(unavailable: {type(exc).__name__})"
            )
            stub.set_defaults(func=_unavailable(module_name, exc))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the command line and run the chosen subcommand; return its exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(func(args) or 0)
    except KeyboardInterrupt:
        print("fence-sorter: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
