"""``fence-sorter emulate SCENE --sensors FILE --bag DIR``: a measured bag with known truth.

Parcels of a stream run through the twin of SCENE (the truth, ``--set`` to change it) one stroke
each, seen by the emulated sensors of FILE (rate, noise, dropouts, latency, camera frame offset;
docs/guide/calibration.md), written without ROS to a bag carrying the measured topics. Seeded: the
same command writes the same bag. Exit codes: 0 written, 2 bad input, 3 a replay failed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fence_sorter.calibration.sensors import SensorConfigError, load_sensors
from fence_sorter.cli.simulate import add_scene_arguments, error, load
from fence_sorter.physics.params import ParameterError


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Run a stream's parcels through the twin and record what emulated "
        "sensors would measure, into a bag for fence-sorter calibrate."
    )
    add_scene_arguments(parser)
    parser.add_argument(
        "--sensors",
        required=True,
        metavar="FILE",
        help="sensors file or name under config/sensors/ (e.g. camera60)",
    )
    parser.add_argument("--bag", required=True, metavar="DIR", help="bag directory to write")
    parser.add_argument("--parcels", type=int, default=20, help="parcels (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="seed of parcels and noise")
    parser.add_argument(
        "--stream",
        default="default",
        help="stream file or name under config/streams/ (default: default)",
    )
    parser.add_argument("--workers", type=int, default=None, help="processes (default: CPUs)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # lazy: loads the kernel (Numba), SciPy, rosbags
    from fence_sorter.calibration.emulate import emulate_bag
    from fence_sorter.calibration.replay import ReplayError
    from fence_sorter.recording.writer import BagWriteError

    if not 1 <= args.parcels <= 10000:
        return error(f"--parcels must be in [1, 10000], got {args.parcels}")
    loaded, code = load(args)
    if loaded is None:
        return code
    try:
        sensors = load_sensors(args.sensors)
        path = emulate_bag(
            Path(args.bag),
            loaded.scenario,
            sensors,
            scene_name=loaded.name,
            stream=args.stream,
            count=args.parcels,
            seed=args.seed,
            workers=args.workers,
        )
    except (SensorConfigError, ParameterError, BagWriteError, OSError) as exc:
        return error(str(exc))
    except ReplayError as exc:
        print(f"fence-sorter: error: {exc}", file=sys.stderr)
        return 3
    print(
        f"fence-sorter emulate: {args.parcels} parcels of {loaded.name} seen by "
        f"{sensors.name} -> {path}"
    )
    return 0
