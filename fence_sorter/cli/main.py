"""``fence-sorter``: the user command line.

Each subcommand lives in its own module ``fence_sorter/cli/<module>.py`` that exposes
``register(parser)``; ``register`` adds the subcommand's arguments to its parser and sets
``func`` (called with the parsed arguments, returns the exit code). To add a subcommand, write
its module and add the command and its one-line help to :data:`SUBCOMMANDS`. Only the module
of the command being run is imported, so ``fence-sorter --help`` and every start-up pay for
one subcommand's imports, not for all of them; a subcommand module imports its heavy
dependencies (the kernel, rclpy, SciPy, ...) inside the function that needs them, so that its
``--help`` stays light too.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from fence_sorter import __version__

#: Subcommand -> its one-line help, in the order of ``--help``. The subcommand ``a-b`` lives in
#: the module ``fence_sorter.cli.a_b``.
SUBCOMMANDS: dict[str, str] = {
    "check": "verify rclpy, ROS 2 and Fast DDS versions, fence_sorter_msgs, ament index, rosbags",
    "demo-roundtrip": "send each fence_sorter_msgs message to an echo node, check it comes back",
    "simulate": "run one sorting event from a scene file",
    "modes": "natural frequencies and tip deflection of a scene's flexible fence",
    "accuracy": "work-precision diagrams: error against wall time for every method",
    "stability": "stability campaign over stiff and extreme cases (invariants and verdicts)",
    "run": "run the node suite on a parcel stream and print a summary",
    "line-sim": "simulate a line of fence units without ROS (routing, recirculation, summary)",
    "replay": "republish a recorded bag over DDS with its original timing (scaled)",
    "analyze": "analyse a recorded bag: per-parcel table, capacity, plots, check vs live outcomes",
    "bag": "bag tools standing in for `ros2 bag` (info)",
    "topic": "topic tools standing in for `ros2 topic` (list, echo, hz) over rclpy",
    "param": "parameter tools standing in for `ros2 param` (list, get, set) over rclpy",
    "rrd": "convert a recorded bag into a Rerun recording (.rrd)",
    "views": "screenshots of a Rerun recording in Rerun's web viewer under headless Chromium",
    "optimize": "maximise the sorting capacity W_t over X = [R_s, v, t1, R_z] (sections 3-4)",
    "emulate": "write a measured bag (encoder, camera, strain) of the twin with known truth",
    "calibrate": "fit friction, contact and fence damping parameters to a measured bag",
    "validate": "predict held-out parcels of a measured bag with a (calibrated) scene",
}


@dataclass(frozen=True)
class CommandLine:
    """A command with subcommands: ``prog``'s subcommand ``a-b`` lives in the module
    ``<package>.a_b``; ``subcommands`` maps each to its one-line help, in ``--help`` order."""

    prog: str
    description: str
    package: str
    subcommands: Mapping[str, str]

    def module_name(self, command: str) -> str:
        """The module under :attr:`package` that defines ``command``."""
        return f"{self.package}.{command.replace('-', '_')}"


#: ``fence-sorter``
FENCE_SORTER = CommandLine(
    "fence-sorter",
    "Digital twin of a rotary active fence parcel sorter.",
    "fence_sorter.cli",
    SUBCOMMANDS,
)


def module_name(command: str) -> str:
    """The module under fence_sorter.cli that defines ``command``."""
    return FENCE_SORTER.module_name(command)


def _unavailable(
    cli: CommandLine, command: str, error: BaseException
) -> Callable[[argparse.Namespace], int]:
    """Return a func that reports why the module of ``command`` cannot be loaded."""

    def func(args: argparse.Namespace) -> int:
        del args
        print(
            f"{cli.prog}: subcommand module {cli.module_name(command)} cannot be loaded: "
            f"{type(error).__name__}: {error}",
            file=sys.stderr,
        )
        return 1

    return func


def build_parser(
    argv: Sequence[str] = (), cli: CommandLine = FENCE_SORTER
) -> argparse.ArgumentParser:
    """Return the top-level parser. Every subcommand is listed with its help; only the one
    named in ``argv`` (if any) is configured, so only its module is imported."""
    parser = argparse.ArgumentParser(prog=cli.prog, description=cli.description)
    parser.add_argument("--version", action="version", version=f"fence-sorter {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    chosen = next((a for a in argv if not a.startswith("-")), None)
    for command, help_text in cli.subcommands.items():
        sub = subparsers.add_parser(command, help=help_text)
        if command == chosen:
            configure(command, sub, cli)
    return parser


def configure(
    command: str, parser: argparse.ArgumentParser, cli: CommandLine = FENCE_SORTER
) -> None:
    """Import the module of ``command`` and let it add its arguments and ``func`` to ``parser``;
    a module that cannot be loaded becomes a subcommand that says why (exit 1), so it cannot
    take the others down."""
    try:
        # lazy: the one dispatch of the command line: only the chosen subcommand's module
        module = importlib.import_module(cli.module_name(command))
        module.register(parser)
    except Exception as exc:
        parser.set_defaults(func=_unavailable(cli, command, exc))


def _interrupt_once(signum: int, frame: object) -> None:
    """SIGINT/SIGTERM until a subcommand installs its own handling: the first raises
    KeyboardInterrupt (exit 130, one line), later ones are ignored so they cannot interrupt
    that exit with a traceback."""
    del frame
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise KeyboardInterrupt(signal.Signals(signum).name)


#: exit status when stdout's reader went away (128 + SIGPIPE, as a shell reports it)
EXIT_BROKEN_PIPE = 141


def main(argv: Sequence[str] | None = None, cli: CommandLine = FENCE_SORTER) -> int:
    """Parse the command line and run the chosen subcommand; return its exit code. As the
    process's own command (``argv`` None) it also owns the signals: Ctrl-C during start-up is
    exit 130 in one line, and none after the command is done changes the exit status. Output
    whose reader has gone (``fence-sorter line-sim LINE | head``) ends the command quietly
    with 141, the status of a process a broken pipe stops."""
    own = argv is None and threading.current_thread() is threading.main_thread()
    if own:
        signal.signal(signal.SIGINT, _interrupt_once)
        signal.signal(signal.SIGTERM, _interrupt_once)
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        parser = build_parser(argv, cli)
        args = parser.parse_args(argv)
        func = getattr(args, "func", None)
        if func is None:
            parser.print_help(sys.stderr)
            code = 2
        else:
            code = int(func(args) or 0)
        if own:
            sys.stdout.flush()  # here, where a reader gone is caught, not at the exit
    except KeyboardInterrupt:
        print(f"{cli.prog}: interrupted", file=sys.stderr)
        code = 130
    except BrokenPipeError:
        # the reader of stdout is gone: nothing more can be said there, and the interpreter's
        # own flush at exit must not fail again on it
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = EXIT_BROKEN_PIPE
    if own:  # the interpreter's exit resets Python-level handlers to default, not SIG_IGN
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
