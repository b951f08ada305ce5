"""``fence-sorter line-sim LINE``: a line of fence units simulated without ROS.

Loads a line file (``config/lines/``), draws the induction stream, runs the line to the drain
(:mod:`fence_sorter.line.multi_unit`) and prints the line summary (``--json``: one JSON object).
``--rrd FILE`` also writes a Rerun recording of the whole line, sampled as sim time passes
(:mod:`fence_sorter.visualisation.line_view`). Exit codes: 0 a drained run with conservation
exact, 0 wrong destinations, every hand-off received at the other end of its link, with the
guard 0 swept-sector intrusions, 0 failed events and no sorted parcel over a limit of
(10)-(12); 1 otherwise (each problem named on stderr); 2 a bad line file or option (one line
naming it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fence_sorter.jsonsafe import json_safe
from fence_sorter.physics.params import ParameterError

EXIT_OK, EXIT_CHECK, EXIT_BAD = 0, 1, 2


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Simulate a sortation line of fence units without ROS."
    parser.add_argument("line", metavar="LINE", help="line file, or a line in config/lines")
    parser.add_argument("--parcels", type=int, default=100, metavar="N", help="stream length")
    parser.add_argument(
        "--duration", type=float, default=None, metavar="S",
        help="induct the parcels arriving within S s instead of --parcels",
    )  # fmt: skip
    parser.add_argument(
        "--rate", type=float, default=None, metavar="PCS_H",
        help="induction rate [pcs/h] (default: the stream's)",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=None, help="stream seed (default: its own)")
    parser.add_argument(
        "--no-guard", action="store_true",
        help="turn the swept-sector guard off (the intrusions it prevents are counted)",
    )  # fmt: skip
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument(
        "--rrd", metavar="FILE", default=None,
        help="write a Rerun recording of the line (top view, per-unit plots) to FILE.rrd",
    )  # fmt: skip
    parser.add_argument(
        "--rrd-period", type=float, default=0.02, metavar="S",
        help="sim time between the recording's samples [s] (default: %(default)s)",
    )  # fmt: skip
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"fence-sorter: error: {msg}", file=sys.stderr)
    return EXIT_BAD


def run(args: argparse.Namespace) -> int:
    if not 1 <= args.parcels <= 10**6:
        return _error(f"--parcels must be in [1, 1000000], got {args.parcels}")
    if args.duration is not None and not 0.0 < args.duration <= 1e6:
        return _error(f"--duration must be in (0, 1e6] s, got {args.duration}")
    if args.rate is not None and not 1.0 <= args.rate <= 1e5:
        return _error(f"--rate must be in [1, 100000] pcs/h, got {args.rate}")
    if args.rrd is not None:
        rrd = Path(args.rrd)
        if rrd.suffix != ".rrd" or not rrd.parent.is_dir():
            return _error(f"--rrd must be a FILE.rrd in an existing directory, got {args.rrd}")
    if not 0.01 <= args.rrd_period <= 10.0:
        return _error(f"--rrd-period must be in [0.01, 10] s, got {args.rrd_period}")
    # lazy: the line's physics loads Numba and the compiled kernel
    from fence_sorter.line.line_file import load_line
    from fence_sorter.line.multi_unit import LinePlant, LineRunConfig, line_problems

    try:
        line = load_line(args.line)
    except (ParameterError, OSError) as exc:
        return _error(str(exc))
    cfg = LineRunConfig(
        parcels=args.parcels if args.duration is None else None,
        duration=args.duration,
        rate_pcs_h=args.rate,
        seed=args.seed,
        guard=not args.no_guard,
    )
    logger = plant = None
    try:
        plant = LinePlant(line, cfg)
        plant.warm_up()
        if args.rrd is not None:
            logger = _recorder(line, args.rrd, args.rrd_period)
            plant.observers.append(logger.observe)
        s = plant.run()
    except ParameterError as exc:
        return _error(str(exc))
    finally:
        if logger is not None:
            logger.close(plant)
    problems = line_problems(s)
    if args.json:
        print(json.dumps(json_safe(s)))
    else:
        print(format_summary(s))
    for problem in problems:
        print(f"fence-sorter line-sim: {problem}", file=sys.stderr)
    return EXIT_CHECK if problems else EXIT_OK


def _recorder(line, path: str, period: float):
    """The line's Rerun logger writing to ``path`` (the line's layout)."""
    # lazy: the line's view reads the line's units (Numba and the compiled kernel)
    from fence_sorter.visualisation.line_view import (
        LineRerunLogger,
        line_blueprint,
        open_recording,
    )

    rec = open_recording(path, layout=lambda paused: line_blueprint(line, paused))
    return LineRerunLogger(rec, line, period=period)


def _steady_line(s: dict) -> str:
    """Throughput in and out over the steady window (:meth:`LinePlant.steady_window`)."""
    w = s["steady_window"]
    if w is None:
        return "throughput: no steady window (the induction ran no longer than a loop cycle)"
    return (
        f"throughput over the steady window [{w['start_s']:.1f}, {w['end_s']:.1f}) s: in "
        f"{s['throughput_in_pcs_h']:.0f} pcs/h ({w['first_inductions']} first inductions), out "
        f"{s['throughput_out_pcs_h']:.0f} pcs/h ({w['sorts']} sorts = "
        f"{w['first_inductions']} - {w['still_on_line']} still on the line - "
        f"{w['ended_unsorted']} rejected or failed + {w['from_before']} from before)"
    )


def format_summary(s: dict) -> str:
    lines = [
        f"line {s['line']}  guard {'on' if s['guard'] else 'off'}  "
        f"sim {s['sim_time_s']:.1f} s in {s['wall_time_s']:.1f} s wall "
        f"({s['real_time_factor']:.1f}x real time)",
        f"inducted {s['parcels_inducted']} ({s['induction_rate_pcs_h']:.0f} pcs/h), sorted "
        f"{s['sorted']} ({s['sort_rate']:.1%}), "
        f"wrong destination {s['sorted_wrong_destination']}, rejected {s['rejected']}, "
        f"no-read {s['no_read']}",
        _steady_line(s),
        f"recirculated {s['recirculated']} ({s['recirculation_share']:.1%}), passes per parcel "
        f"{s['passes_per_parcel']:.2f}, swept-sector intrusions {s['swept_sector_intrusions']}",
        "limits: "
        + (
            "; ".join(
                f"({c}) {len(ids)} sorted parcels over it {ids[:20]}"
                for c, ids in s.get("parcels_over_limits", {}).items()
                if ids
            )
            or "every sorted parcel within (10)-(12)"
        )
        + f"; failed events {s['solver_failures']}",
        "per destination: "
        + ", ".join(f"{d} {n}" for d, n in s["sorted_per_destination"].items()),
    ]
    for name, u in s["units"].items():
        dec = ", ".join(f"{k} {v}" for k, v in u["declined"].items() if v)
        lines.append(
            f"{name} ({u['side']}, {u['position_m']:g} m): strokes {u['strokes']}, sorted "
            f"{u['sorted']}, missed {u['missed']}, utilisation {u['utilisation']:.1%}, peak N "
            f"{u['peak_normal_force_N']:.0f} N, margins w {u['impact_speed_margin_m_s']:.2f} m/s"
            f" a {u['accel_margin_m_s2']:.0f} m/s^2, intrusions {u['swept_sector_intrusions']};"
            f" declined: {dec or 'none'}"
        )
    links = s["links"]
    lines.append(
        "hand-offs sent/received: "
        + ", ".join(f"{k} {v['sent']}/{v['received']}" for k, v in links.items())
        + f"; refused {sum(sum(v['refused'].values()) for v in links.values())}"
        + f", lost {sum(v['lost'] for v in links.values())}"
    )
    for name, d in s.get("units_down", {}).items():
        lost = ", ".join(map(str, d["lost_parcels"])) or "none"
        lines.append(
            f"{name} went down {d['downs']}x ({d['why']}), down {d['downtime_s']:.2f} s of sim "
            f"time, {_seconds(d.get('downtime_wall_s'))} of wall time, rejoined "
            f"{d['rejoins']}x{', down at the end' if d['down_at_end'] else ''}, "
            f"restarts {s.get('restarts', {}).get(name, 0)}; lost with it (in its strokes): "
            f"{lost}; hand-offs passed on for it: {d['handoffs_passed_on']}"
        )
    lost = s.get("lost_with_unit", 0)
    lines.append(
        f"conservation: {s['parcels_inducted']} = sorted {s['sorted']} + rejected "
        f"{s['rejected']} + failed {s['solver_failures']} + on the line {s['still_on_line']}"
        + (f" + lost with a unit {lost}" if lost else "")
        + f": {'exact' if s['conservation_ok'] else 'VIOLATED'}"
    )
    return "\n".join(lines)


def _seconds(v: object) -> str:
    """A wall time [s] of a summary (None: not known, as JSON writes NaN)."""
    return f"{v:.2f} s" if isinstance(v, int | float) else "unknown s"
