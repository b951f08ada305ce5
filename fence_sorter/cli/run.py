"""``fence-sorter run``: the node suite (simulator, scanner, controller, recorder with --bag)
as separate processes on an isolated ROS domain; stops when every parcel has its outcome or on
Ctrl-C, then prints a summary.

Exit codes: 0 a clean run, 1 a node failed or the run could not start, 2 bad input (one line
naming the option and its range), 3 a divert parcel of the run's stream got no outcome, 4
foreign traffic (another run's parcels or commands) was seen, 130 interrupted (README table).
``--rrd FILE``: the simulator saves a Rerun recording of the run (logged live in a child
process, fence_sorter.visualisation.rerun_live).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from fence_sorter.cli.line_sim import format_summary as line_summary
from fence_sorter.cli.simulate import add_set_argument
from fence_sorter.jsonsafe import json_safe
from fence_sorter.runner.job import BadInput, RunOptions, StopRequest, run_job
from fence_sorter.runner.summary import format_summary, summary_for_json


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Start simulator, scanner and controller (and the recorder with --bag) as "
        "separate processes on an isolated ROS domain, run the stream, stop cleanly, summarise."
    )
    parser.add_argument("--scene", default="impact_flexible", help="scene file or name")
    add_set_argument(parser)
    parser.add_argument(
        "--line",
        metavar="LINE",
        help="run a line of fence units instead (a file or a name in config/lines): one "
        "process per unit and the line's owner, in lockstep; with --parcels or --duration, "
        "--rate, --no-guard, --rtf (default 0 with --line: unpaced), --seed, --json, --bag, "
        "--rrd, --rerun-url, --live-rrd, --view-period, --domain, --timeout, --log-dir, "
        "--keep-logs, --units, --no-owner, --interface, --peers, --reply-timeout, "
        "--owner-timeout (docs/guide/line.md)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        metavar="PCS_H",
        help="arrival rate [pcs/h], in [1, 100000]: the stream config's parcel mix drawn at "
        "this rate instead of its own spacing (not for a CSV manifest); with --line the "
        "induction rate of the line's stream (default: the stream's own)",
    )
    parser.add_argument(
        "--no-guard",
        action="store_true",
        help="with --line: the units' swept-sector guard off (the intrusions are counted)",
    )
    parser.add_argument(
        "--units",
        metavar="A[,B...]",
        help="with --line: start only these units here (numbers 1..N or names; default all); "
        "the other units run on another host, on the same --domain",
    )
    parser.add_argument(
        "--no-owner",
        action="store_true",
        help="with --line: another host runs the line's owner (induction, recirculation, clock)",
    )
    parser.add_argument(
        "--rerun-url",
        metavar="URL",
        help="with --line: stream the line's live view to the Rerun viewer listening at URL "
        "(e.g. rerun+http://127.0.0.1:9876/proxy, the viewer started with `rerun`); the "
        "units put their view on the wire every --view-period of sim time",
    )
    parser.add_argument(
        "--live-rrd",
        metavar="FILE",
        help="with --line: save the line's live view (as --rerun-url streams it) to FILE",
    )
    parser.add_argument(
        "--view-period",
        type=float,
        metavar="S",
        help="with --line: sim time between the units' view samples [s] (default 0.05 with "
        "--rerun-url or --live-rrd, else 0: none; a --no-owner host's units need it for the "
        "owner's live view)",
    )
    parser.add_argument(
        "--reply-timeout",
        type=float,
        metavar="S",
        help="with --line: the owner takes a unit that does not answer a command within S s "
        "of wall time for down and goes on without it (default 10)",
    )
    parser.add_argument(
        "--owner-timeout",
        type=float,
        metavar="S",
        help="with --line: a unit (and a runner with --no-owner) exits 3 once no command "
        "came from the line's owner for S s of wall time (default 20; above the owner's "
        "--reply-timeout)",
    )
    amount = parser.add_mutually_exclusive_group()
    amount.add_argument("--parcels", type=int, help="parcels to inject (default 20)")
    amount.add_argument("--duration", type=float, help="inject the parcels arriving within S s")
    parser.add_argument(
        "--rtf",
        type=float,
        help="real-time factor (0: as fast as it can; default 1, with --line 0)",
    )
    parser.add_argument("--bag", metavar="DIR", help="record the run (rosbag2 MCAP) into DIR")
    parser.add_argument(
        "--rrd",
        metavar="FILE",
        help="save a Rerun recording of the run (the simulator logs it live; with --line: the "
        "line view, written from the run's bag at its end, every parcel and sorted parcels' "
        "damage margins; live: --rerun-url, --live-rrd; view: rerun FILE)",
    )
    parser.add_argument(
        "--sensors",
        metavar="FILE",
        help="sensors file or name under config/sensors/ (e.g. camera60): the sensors node "
        "publishes the measured topics from the twin's state; with --bag a calibration bag "
        "(the truth in its metadata; docs/guide/calibration.md)",
    )
    parser.add_argument(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="serve every topic of the run to the Foxglove app over the Foxglove WebSocket "
        "protocol at ws://HOST:PORT (HOST default 127.0.0.1; docs/guide/foxglove.md)",
    )
    parser.add_argument(
        "--stream", default="default", help="stream config (YAML) or CSV manifest, or a name"
    )
    parser.add_argument("--seed", type=int, help="seed of a random stream (default: the file's)")
    parser.add_argument(
        "--timeout", type=float, help="wall-time limit [s] (default: from the stream)"
    )
    parser.add_argument(
        "--log-dir",
        help="node logs (default: a new temporary directory, removed after a clean run)",
    )
    parser.add_argument(
        "--keep-logs", action="store_true", help="keep the log directory of a clean run too"
    )
    parser.add_argument(
        "--domain",
        type=int,
        metavar="N",
        help="ROS domain of the run, 0-232 (default: ROS_DOMAIN_ID if set, else a free one "
        "of 201-232); refused if another participant on this host uses it",
    )
    parser.add_argument(
        "--interface",
        metavar="ADDRESS",
        help="talk to other hosts: UDP on this host's IPv4 ADDRESS only (with --peers; default: "
        "this host alone, shared memory and loopback)",
    )
    parser.add_argument(
        "--peers",
        metavar="A[,B...]",
        help="the other hosts' IPv4 addresses, found by unicast discovery (with --interface)",
    )
    add_param_option(
        parser, "node parameter override, e.g. controller:max_evaluations=5 (repeatable)"
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.set_defaults(func=run)


def add_param_option(parser: argparse.ArgumentParser, help: str) -> None:
    """``--param NODE:KEY=VALUE`` (repeatable) into ``args.params``; checked by the job."""
    parser.add_argument(
        "--param", dest="params", action="append", default=[], metavar="NODE:KEY=VALUE", help=help
    )


def run(args: argparse.Namespace) -> int:
    if args.line is not None:
        return _run_line(args)
    for opt, given in (
        ("--units", args.units is not None),
        ("--no-owner", args.no_owner),
        ("--no-guard", args.no_guard),
        ("--rerun-url", args.rerun_url is not None),
        ("--live-rrd", args.live_rrd is not None),
        ("--view-period", args.view_period is not None),
        ("--reply-timeout", args.reply_timeout is not None),
        ("--owner-timeout", args.owner_timeout is not None),
    ):
        if given:
            print(f"fence-sorter: error: {opt} goes with --line only", file=sys.stderr)
            return 2
    opts = RunOptions(
        scene=args.scene,
        parcels=args.parcels,
        duration=args.duration,
        rtf=1.0 if args.rtf is None else args.rtf,
        bag=args.bag,
        rrd=args.rrd,
        stream=args.stream,
        seed=args.seed,
        timeout=args.timeout,
        log_dir=args.log_dir,
        params=args.params,
        domain=args.domain,
        keep_logs=args.keep_logs,
        sensors=args.sensors,
        foxglove=args.foxglove,
        interface=args.interface,
        peers=args.peers,
        overrides=args.overrides,
        rate=args.rate,
    )
    say = (lambda s: print(s, file=sys.stderr)) if args.json else print
    # from here to the exit SIGINT/SIGTERM are flags the job checks (no traceback, no
    # half-done start or stop)
    stop = StopRequest()
    stop.install()
    try:
        return _run_and_report(args, opts, say, stop)
    except BadInput as exc:
        print(f"fence-sorter: error: {exc}", file=sys.stderr)
        return 2
    finally:
        stop.restore()


#: the options of a single-unit run that a line run does not take
_NOT_FOR_LINE = ("sensors", "foxglove")


def _run_line(args: argparse.Namespace) -> int:
    for name in _NOT_FOR_LINE:
        if getattr(args, name) is not None:
            opt = "--" + name.replace("_", "-")
            print(f"fence-sorter: error: {opt} does not go with --line", file=sys.stderr)
            return 2
    if args.params or args.stream != "default" or args.overrides:
        print("fence-sorter: error: --param, --set and --stream do not go with --line "
              "(the line file names its units and its stream)", file=sys.stderr)  # fmt: skip
        return 2
    rrd = Path(args.rrd) if args.rrd is not None else None
    if rrd is not None and (rrd.suffix != ".rrd" or not rrd.resolve().parent.is_dir()):
        print(f"fence-sorter: error: --rrd must be a .rrd file in an existing directory, got "
              f"{args.rrd}", file=sys.stderr)  # fmt: skip
        return 2
    if rrd is not None and args.no_owner:
        print("fence-sorter: error: --rrd is written on the owner's host: it does not go with "
              "--no-owner", file=sys.stderr)  # fmt: skip
        return 2
    if args.reply_timeout is not None and args.no_owner:
        print("fence-sorter: error: --reply-timeout is the owner's: it does not go with "
              "--no-owner", file=sys.stderr)  # fmt: skip
        return 2
    if rrd is None or args.bag is not None:
        return _run_line_job(args, args.bag, rrd)
    # --rrd without --bag: the view is written from a bag of the run all the same
    with tempfile.TemporaryDirectory(prefix="fence_sorter_line_bag_") as scratch:
        return _run_line_job(args, str(Path(scratch) / "bag"), rrd)


def _run_line_job(args: argparse.Namespace, bag: str | None, rrd: Path | None) -> int:
    # lazy: the line's runner loads the line's physics (Numba) for the line file's check
    from fence_sorter.runner.line_job import LineRunOptions, run_line_job

    opts = LineRunOptions(
        line=args.line,
        parcels=10 if args.parcels is None else args.parcels,
        duration=args.duration,
        rate=args.rate,
        guard=not args.no_guard,
        rtf=0.0 if args.rtf is None else args.rtf,
        seed=args.seed,
        domain=args.domain,
        log_dir=args.log_dir,
        keep_logs=args.keep_logs,
        timeout=3600.0 if args.timeout is None else args.timeout,
        units=args.units,
        owner=not args.no_owner,
        interface=args.interface,
        peers=args.peers,
        bag=bag,
        live_rrd=args.live_rrd,
        rerun_url=args.rerun_url,
        view_period=args.view_period,
    )
    if args.reply_timeout is not None:
        opts = replace(opts, reply_timeout=args.reply_timeout)
    if args.owner_timeout is not None:
        opts = replace(opts, owner_timeout=args.owner_timeout)
    say = (lambda s: print(s, file=sys.stderr)) if args.json else print
    stop = StopRequest()
    stop.install()
    try:
        result = run_line_job(opts, say=say, stop=stop)
    finally:
        stop.restore()
    if result.code == 2:
        print(f"fence-sorter: error: {result.message}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(json_safe(result.summary)))
    elif result.summary.get("units_here") and result.code == 0:
        print(f"line {result.summary['line']}: {', '.join(result.summary['units_here'])} "
              "ended with the line (the line summary: on the owner's host)")  # fmt: skip
    elif result.summary.get("line"):
        print(line_summary(result.summary))
        if "pacing" in result.summary:
            print(pacing_line(result.summary["pacing"]))
    if result.code != 0:
        print(f"fence-sorter run --line: {result.message}", file=sys.stderr)
    if rrd is not None and result.summary.get("line") and bag is not None:
        view = _line_view(Path(bag), rrd, say)
        return result.code or view
    return result.code


def _line_view(bag: Path, rrd: Path, say) -> int:
    """--rrd of a line run: the line view written from the run's bag (the units' fences are
    not on the wire: each unit is simulated again from its recorded commands and every reply
    checked against the recorded one, as ``fence-sorter rrd BAG`` does)."""
    # lazy: rosbags and the line's units (Numba) load only for --rrd
    from fence_sorter.recording.bagread import BagReadError, read_bag
    from fence_sorter.visualisation.line_bag_view import write_line_view

    try:
        contents = read_bag(bag)
    except BagReadError as exc:
        print(f"fence-sorter run --line: --rrd: {exc}", file=sys.stderr)
        return 1
    return write_line_view(contents, rrd, say=say, warn=_warn)  # say: stderr with --json


def _warn(line: str) -> None:
    print(f"fence-sorter run --line: {line}", file=sys.stderr)


def pacing_line(p: dict) -> str:
    """One line on the line clock's pacing (the owner's ``PacedSteps`` figures)."""
    if not p["real_time_factor_target"]:
        return f"line clock: unpaced, {p['steps']} steps"
    return (
        f"line clock: rtf {p['real_time_factor_target']:g}, {p['steps']} steps, deadline "
        f"misses {p['deadline_misses']} of {p['cycles']} ({p['deadline_miss_share']:.2%}), "
        f"slips {p['catch_up_slips']}, lateness p99 {p['lateness_p99_ms']:.2f} ms"
    )


def _run_and_report(args: argparse.Namespace, opts, say, stop) -> int:
    result = run_job(opts, say=say, stop=stop)
    if args.json:
        print(
            json.dumps(
                summary_for_json(
                    {**result.summary, "exit": result.code, "message": result.message}
                )
            )
        )
    else:
        print(format_summary(result.summary))
    if result.code != 0:
        kept = result.summary.get("log_dir")
        print(
            f"fence-sorter run: {result.message}" + (f" (logs: {kept})" if kept else ""),
            file=sys.stderr,
        )
    return result.code
