"""``fence-sorter line-sim LINE``: a line of fence units simulated without ROS.

Loads a line file (``config/lines/``), draws the induction stream, runs the line to the drain
(:mod:`fence_sorter.line.multi_unit`) and prints the line summary (``--json``: one JSON object).
``--rrd FILE`` also writes a Rerun recording of the whole line, sampled as sim time passes
(:mod:`fence_sorter.visualisation.line_view`). ``--parcels-out FILE`` writes one row per
parcel (:mod:`fence_sorter.line.parcel_log`; CSV, or Parquet for ``FILE.parquet``);
``--json --with-parcels`` puts the same rows under ``parcels``. Exit codes: 0 a drained run
with conservation exact, 0 wrong destinations, every hand-off received at the other end of
its link, with the guard 0 swept-sector intrusions, 0 failed events and no sorted parcel over
a limit of (10)-(12); 1 otherwise (each problem named on stderr); 2 a bad line file or option
(one line naming it).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

from fence_sorter.jsonsafe import json_safe
from fence_sorter.line.parcel_log import parcel_rows, write_rows
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
        "--parcels-out", metavar="FILE", default=None,
        help="write one row per parcel to FILE (.csv, or .parquet)",
    )  # fmt: skip
    parser.add_argument(
        "--with-parcels", action="store_true",
        help="with --json: the per-parcel rows under 'parcels'",
    )  # fmt: skip
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
    if args.parcels_out is not None:
        out = Path(args.parcels_out)
        if out.suffix not in (".csv", ".parquet") or not out.parent.is_dir():
            return _error(
                "--parcels-out must be a FILE.csv or FILE.parquet in an existing directory, "
                f"got {args.parcels_out}"
            )
        if out.suffix == ".parquet" and importlib.util.find_spec("pyarrow") is None:
            return _error("--parcels-out FILE.parquet needs pyarrow, not installed: use .csv")
    if args.with_parcels and not args.json:
        return _error("--with-parcels goes with --json only")
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
    if args.parcels_out is not None or args.with_parcels:
        rows = parcel_rows(plant)
        if args.parcels_out is not None:
            write_rows(rows, args.parcels_out)
        if args.with_parcels:
            s = {**s, "parcels": rows}
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
    """Throughput of the cohort first inducted in the steady window
    (:mod:`fence_sorter.line.steady`), inducted against offered, and saturation."""
    w, st = s["steady_window"], s.get("steady")
    if st is None:  # a summary from before the cohort's figures
        return "throughput: no cohort figures in this summary"
    sat = (
        f"SATURATED: offered {st['offered_pcs_h']:.0f}, inducted "
        f"{st['inducted_pcs_h']:.0f} pcs/h; queue at {', '.join(st['queue_at']) or 'none'}"
        if st["saturated"]
        else "not saturated"
    ) + (
        f" (induction wait grows {st['induction_delay_growth']:.3f} s/s, merge wait "
        f"{st['merge_wait_growth']:.3f} s/s)"
    )
    if w is None:
        return (
            "throughput: no steady window (the induction ran no longer than a loop cycle); " + sat
        )
    c = st["cohort"]
    return (
        f"throughput of the {c['inducted']} parcels first inducted in the steady window "
        f"[{w['start_s']:.1f}, {w['end_s']:.1f}) s: in {st['inducted_pcs_h']:.0f} pcs/h "
        f"= {st['inducted_over_offered']:.1%} of {st['offered_pcs_h']:.0f} offered, out "
        f"{st['sorted_pcs_h']:.0f} pcs/h (out/in {st['out_over_in']:.3f}: sorted "
        f"{c['sorted']}, rejected {c['rejected']}, failed {c['failed']}"
        + (f", lost with a unit {c['lost_with_unit']}" if c["lost_with_unit"] else "")
        + f", on the line at the end {c['on_line']})\n"
        + sat
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
