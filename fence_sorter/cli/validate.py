"""``fence-sorter validate BAG --scene CALIBRATED``: predict held-out parcels, compare.

For each selected parcel (``--last N``: the bag's last N, as ``calibrate --holdout N`` left
out; ``--parcels``: by id; default all) the twin of the scene replays the parcel and its stroke;
sorted or not, exit speed, y_max and peak acceleration are estimated the same way from the
measured and the predicted camera track and compared (docs/guide/calibration.md). ``--out DIR``
writes validation.json and validation.png. Exit codes: 0 compared, 2 bad input, 3 a replay
failed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fence_sorter.cli.calibrate import add_bag_scene_arguments, load_bag_and_scene
from fence_sorter.cli.simulate import error


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Compare the twin's predictions with the measured parcels of a bag."
    add_bag_scene_arguments(parser, "scene to validate (file or name), e.g. a calibrated one")
    parser.add_argument(
        "--last",
        type=int,
        default=0,
        metavar="N",
        help="only the bag's last N parcels (calibrate --holdout N)",
    )
    parser.add_argument("--parcels", metavar="IDS", help="only these parcel ids (comma-separated)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # lazy: loads the kernel (Numba), SciPy, rosbags
    from fence_sorter.calibration.events import CalibrationInputError, FitError
    from fence_sorter.calibration.validate import plot_checks, validate

    if args.last < 0:
        return error(f"--last must be in [0, inf), got {args.last}")
    mb, loaded, code = load_bag_and_scene(args)
    if mb is None:
        return code
    if args.parcels:
        try:
            ids = {int(v) for v in args.parcels.split(",") if v.strip()}
        except ValueError:
            return error(f"--parcels must be comma-separated parcel ids, got {args.parcels!r}")
        missing = ids - {e.parcel_id for e in mb.events}
        if missing:
            return error(f"--parcels: no parcel {min(missing)} with a stroke in {args.bag}")
        mb.events = [e for e in mb.events if e.parcel_id in ids]
    if args.last:
        mb.events = mb.events[-args.last :]
    try:
        checks, summary = validate(loaded.scenario, mb, args.workers)
    except CalibrationInputError as exc:
        return error(str(exc))
    except FitError as exc:
        print(f"fence-sorter validate: {exc}", file=sys.stderr)
        return 3
    out = {"scene": loaded.name, "summary": summary, "parcels": [c.to_dict() for c in checks]}
    if args.out:
        d = Path(args.out)
        d.mkdir(parents=True, exist_ok=True)
        plot_checks(checks, d / "validation.png")
        (d / "validation.json").write_text(json.dumps(out, indent=1), encoding="utf-8")
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(
        f"{'parcel':>7} {'sorted m/p':>11} {'exit m/s meas':>14} {'pred':>7} "
        f"{'y_max m meas':>13} {'pred':>7} {'peak a meas':>12} {'pred':>8}"
    )
    for c in checks:
        m, p = c.measured, c.predicted
        print(
            f"{c.parcel_id:>7} {str(m['sorted'])[0]}/{str(p['sorted'])[0]:>9} "
            f"{m['exit_speed']:>14.3f} {p['exit_speed']:>7.3f} {m['y_max']:>13.3f} "
            f"{p['y_max']:>7.3f} {m['peak_accel']:>12.1f} {p['peak_accel']:>8.1f}"
        )
    s = summary
    print(f"\n{s['parcels']} parcels, sorted agrees for {s['sorted_agree']}")
    for key in ("exit_speed", "y_max", "peak_accel"):
        e = s[key]
        if e["n"]:
            print(
                f"{key}: RMS error {e['rms_error']:.4g}, max {e['max_abs_error']:.4g} "
                f"({e['n']} parcels)"
            )
    return 0
