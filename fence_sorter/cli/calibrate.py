"""``fence-sorter calibrate BAG --fit NAMES``: fit the twin's physics to a measured bag.

Aligns the camera and the strokes, replays every parcel on the twin and fits the named
parameters by robust nonlinear least squares; prints each estimate with its 95 % interval, the
correlation matrix and an identifiability verdict (a parameter the data cannot determine is
flagged and no number is given for it). ``--out DIR`` writes calibration.json, the calibrated
scene (``<scene>_calibrated.yaml``) and residuals.png. Exit codes: 0 fitted, 2 bad input (no
measured topics, too few parcels, a parameter the scene does not have), 3 the fit failed.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from tqdm import tqdm

from fence_sorter.cli.simulate import add_set_argument, error
from fence_sorter.physics.params import ParameterError
from fence_sorter.scene import load_scene


def add_bag_scene_arguments(parser: argparse.ArgumentParser, scene_help: str) -> None:
    """BAG, --scene, --set, --workers, --json, --out: shared with ``fence-sorter validate``."""
    parser.add_argument("bag", metavar="BAG", help="bag directory with the measured topics")
    parser.add_argument("--scene", help=scene_help)
    add_set_argument(parser)
    parser.add_argument("--workers", type=int, default=None, help="processes (default: CPUs)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--out", metavar="DIR", help="write the result files here")


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Fit the twin's physics parameters to the measured topics of a bag."
    add_bag_scene_arguments(
        parser, "prior scene (file or name; default: the scene an emulated bag names)"
    )
    parser.add_argument(
        "--fit",
        required=True,
        metavar="NAMES",
        help="comma-separated: mu_belt,mu_fence,k_p,b_p,fence.damping_ratio",
    )
    parser.add_argument(
        "--holdout",
        type=int,
        default=0,
        metavar="N",
        help="leave the bag's last N parcels out (for fence-sorter validate)",
    )
    parser.add_argument(
        "--bootstrap",
        type=int,
        default=0,
        metavar="B",
        help="check the intervals by B parametric bootstrap refits",
    )
    parser.add_argument(
        "--max-ci-factor",
        type=float,
        default=2.718281828,
        metavar="F",
        help="flag a parameter whose 95 %% interval spans more than a factor F (default e)",
    )
    parser.add_argument(
        "--max-pose-scatter",
        type=float,
        default=math.sqrt(2.0),
        metavar="F",
        help="the largest RMS of the fitted camera positions' residuals, in units of their "
        "noise before the strokes, taken as a fit (default sqrt(2)); above it the fit "
        "restarts, then fails with exit 3",
    )
    parser.add_argument(
        "--starts",
        type=int,
        default=1,
        metavar="N",
        help="fit again from N-1 further starts along the least determined directions and "
        "keep the lowest (default 1; use 2 on a stiff fence, where the contact stiffness and "
        "damping can stay near the prior)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the bootstrap's noise")
    parser.add_argument(
        "--max-evaluations",
        type=int,
        default=40,
        metavar="N",
        help="residual evaluations per least-squares stage (default 40)",
    )
    add_scheduler_argument(parser)
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=run)


def add_scheduler_argument(parser: argparse.ArgumentParser) -> None:
    """--scheduler: how the parcels' replays run in parallel (shared with calibrate-bench)."""
    parser.add_argument(
        "--scheduler",
        default="processes",
        metavar="S",
        help="processes (default: forked processes), dask (the same processes driven by "
        "Dask) or a Dask scheduler address, e.g. tcp://127.0.0.1:8786",
    )


def load_bag_and_scene(args):
    """(MeasuredBag, LoadedScene, None) or (None, None, exit code)."""
    # lazy: loads the kernel (Numba), SciPy, rosbags
    from fence_sorter.calibration.bag import MeasuredBagError, read_measured_bag
    from fence_sorter.recording.bagread import BagReadError

    try:
        mb = read_measured_bag(Path(args.bag))
    except (BagReadError, MeasuredBagError) as exc:
        return None, None, error(str(exc))
    scene = args.scene or (mb.truth or {}).get("scene")
    if not scene:
        return None, None, error("--scene is required: the bag names no scene")
    try:
        loaded = load_scene(scene, args.overrides)
    except (ParameterError, OSError) as exc:
        return None, None, error(str(exc))
    return mb, loaded, None


def run(args: argparse.Namespace) -> int:
    # lazy: loads the kernel (Numba), SciPy, rosbags
    from fence_sorter.calibration.evaluate import check_scheduler
    from fence_sorter.calibration.events import CalibrationInputError, FitError
    from fence_sorter.calibration.fit import calibrate, check_fit_names
    from fence_sorter.calibration.report import format_result, plot_residuals, write_scene

    if args.bootstrap < 0 or args.holdout < 0:
        return error("--bootstrap and --holdout must be in [0, inf)")
    if args.max_evaluations < 1:
        return error(f"--max-evaluations must be in [1, inf), got {args.max_evaluations}")
    if not args.max_ci_factor > 1.0:
        return error(f"--max-ci-factor must be in (1, inf), got {args.max_ci_factor}")
    if args.starts < 1:
        return error(f"--starts must be in [1, inf), got {args.starts}")
    if not args.max_pose_scatter >= 1.0:
        return error(f"--max-pose-scatter must be in [1, inf), got {args.max_pose_scatter}")
    try:
        check_scheduler(args.scheduler)
    except CalibrationInputError as exc:
        return error(str(exc))
    mb, loaded, code = load_bag_and_scene(args)
    if mb is None:
        return code
    try:
        names = check_fit_names(
            loaded.scenario, [n.strip() for n in args.fit.split(",") if n.strip()], loaded.name
        )
    except CalibrationInputError as exc:
        return error(str(exc))
    held = (
        [e.parcel_id for e in mb.events[len(mb.events) - args.holdout :]] if args.holdout else []
    )
    mb.events = mb.events[: len(mb.events) - args.holdout]
    bar = tqdm(
        desc="calibrate: replays",
        unit=" replays",
        disable=args.no_progress,
        file=sys.stderr,
        leave=False,
    )
    try:
        res = calibrate(
            loaded.scenario,
            mb,
            names,
            workers=args.workers,
            scheduler=args.scheduler,
            max_log_halfwidth=0.5 * math.log(args.max_ci_factor),
            bootstrap=args.bootstrap,
            seed=args.seed,
            progress=bar.update,
            max_nfev=args.max_evaluations,
            max_pose_scatter=args.max_pose_scatter,
            starts=args.starts,
        )
    except CalibrationInputError as exc:
        return error(str(exc))
    except FitError as exc:
        print(f"fence-sorter calibrate: fit failed: {exc}", file=sys.stderr)
        return 3
    finally:
        bar.close()
    out = res.to_dict()
    out["held_out_parcels"] = held
    out["scene"] = loaded.name
    if args.out:
        d = Path(args.out)
        d.mkdir(parents=True, exist_ok=True)
        note = (
            f"{loaded.name} calibrated by fence-sorter calibrate {args.bag} --fit {args.fit}\n"
            "identified: " + ", ".join(f"{k} = {v:.6g}" for k, v in res.values().items())
        )
        scene_path = write_scene(
            loaded.source_path, res.values(), d / f"{loaded.name}_calibrated.yaml", note
        )
        plot = plot_residuals(res.data, res, d / "residuals.png")
        out["files"] = {"scene": str(scene_path), "residuals_plot": str(plot)}
        (d / "calibration.json").write_text(json.dumps(out, indent=1), encoding="utf-8")
    if args.json:
        print(json.dumps(out, indent=1))
    else:
        print(format_result(res))
        if args.out:
            print(
                f"\nwrote {out['files']['scene']}, {out['files']['residuals_plot']}, "
                f"{Path(args.out) / 'calibration.json'}"
            )
    return 0
