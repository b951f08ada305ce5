"""``fence-sorter``: the user command line.

Each subcommand lives in its own module ``fence_sorter/cli/<module>.py`` that exposes
``register(subparsers)``; ``register`` adds the subcommand's parser and sets ``func`` (called
with the parsed arguments, returns the exit code). To add a subcommand, write its module and
append the module name to :data:`SUBCOMMAND_MODULES`.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading
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


def _interrupt_once(signum: int, frame: object) -> None:
    """SIGINT/SIGTERM until a subcommand installs its own handling: the first raises
    KeyboardInterrupt (exit 130, one line), later ones are ignored so they cannot interrupt
    that exit with a traceback."""
    del frame
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise KeyboardInterrupt(signal.Signals(signum).name)


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the command line and run the chosen subcommand; return its exit code. As the
    process's own command (``argv`` None) it also owns the signals: Ctrl-C during start-up is
    exit 130 in one line, and none after the command is done changes the exit status."""
    own = argv is None and threading.current_thread() is threading.main_thread()
    if own:
        signal.signal(signal.SIGINT, _interrupt_once)
        signal.signal(signal.SIGTERM, _interrupt_once)
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        func = getattr(args, "func", None)
        if func is None:
            parser.print_help(sys.stderr)
            code = 2
        else:
            code = int(func(args) or 0)
    except KeyboardInterrupt:
        print("fence-sorter: interrupted", file=sys.stderr)
        code = 130
    if own:  # the interpreter's exit resets Python-level handlers to default, not SIG_IGN
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
