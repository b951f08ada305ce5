"""``fence-sorter simulate SCENE``: run one sorting event from a scene file and report it.

Exit codes: 0 the solve finished (sorted or not), 3 the solve failed (diagnosis printed),
2 the scene or an override is invalid (one line ``fence-sorter: error: ...``, no traceback).
Warnings (e.g. a belt speed beyond the paper's range) go to stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from fence_sorter.physics.params import ParameterError
from fence_sorter.scene import load_scene

EXIT_OK = 0
EXIT_BAD_SCENE = 2
EXIT_SOLVE_FAILED = 3


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """SCENE and --set, shared with ``fence-sorter modes``."""
    parser.add_argument(
        "scene", metavar="SCENE", help="scene file, or the name of a shipped scene"
    )
    add_set_argument(parser)


def add_set_argument(parser: argparse.ArgumentParser) -> None:
    """--set KEY=VALUE (repeatable) into ``overrides``."""
    parser.add_argument(
        "--set",
        dest="overrides",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="override a scene value by its dotted key, e.g. parcel.mass=50 (repeatable)",
    )


def error(message: str) -> int:
    """Print the one-line error of a bad scene or override; return exit code 2."""
    print(f"fence-sorter: error: {message}", file=sys.stderr)
    return EXIT_BAD_SCENE


def load(args: argparse.Namespace):
    """Load the scene named on the command line; (LoadedScene, None) or (None, exit code)."""
    try:
        loaded = load_scene(args.scene, args.overrides)
    except (ParameterError, OSError) as exc:
        return None, error(str(exc))
    for w in loaded.warnings:
        print(f"fence-sorter: warning: {w}", file=sys.stderr)
    return loaded, None


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Run one sorting event from a scene file and print its outcome."
    add_scene_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the outcome as one JSON object")
    parser.set_defaults(func=run)


def _fmt(value: float | None, spec: str, unit: str = "") -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value:{spec}}{' ' + unit if unit else ''}"


def summary(name: str, result) -> str:
    """Human-readable outcome."""
    r = result
    ratio = (
        r.peak_contact_force / r.peak_contact_force_stiff
        if r.peak_contact_force_stiff > 0.0
        else math.nan
    )
    lines = [
        f"scene          {name}",
        f"sorted         {'yes' if r.sorted else 'no'}: {r.reason}",
        f"peak N         {_fmt(r.peak_contact_force, '.1f', 'N')}",
        f"peak N_stiff   {_fmt(r.peak_contact_force_stiff, '.1f', 'N')}"
        f"   (N / N_stiff = {_fmt(ratio, '.3f')})",
        f"peak a_N       {_fmt(r.peak_normal_accel, '.2f', 'm/s^2')}",
        f"impact w_n     {_fmt(r.impact_normal_speed, '.3f', 'm/s')}",
        f"exit speed     {_fmt(r.exit_speed_y, '.3f', 'm/s')} (ydot at y0 = s)",
        f"y_max          {_fmt(r.y_max, '.3f', 'm')}",
    ]
    if any(p == "fem_fence" for p in r.model_parts):
        lines.append(f"peak tip defl. {_fmt(r.peak_tip_deflection * 1e3, '.2f', 'mm')}")
    stages = ", ".join(f"{s}@{t:.3f}s" for s, t in r.stages)
    lines.append(f"stages         {stages}")
    lines.append(
        f"time           sim {r.sim_time:.3f} s, wall {r.wall_time:.3f} s, "
        f"{r.steps} steps ({r.rejected_steps} rejected)"
    )
    if not r.success:
        lines.append(f"SOLVE FAILED   {r.diagnosis}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    loaded, code = load(args)
    if loaded is None:
        return code
    # lazy: loads the kernel (Numba), SciPy
    from fence_sorter.physics.simulate import SortingModel, simulate

    try:
        model = SortingModel(loaded.scenario)
    except ValueError as exc:  # a model the validated parameters still cannot build
        return error(f"scene {loaded.source_path.name}: {exc}")
    result = simulate(loaded.scenario, model)
    if args.json:
        out = result.to_dict()
        out["scene"] = loaded.name
        out["warnings"] = list(loaded.warnings)
        print(json.dumps(out))
    else:
        print(summary(loaded.name, result))
    if not result.success:
        print(f"fence-sorter: solve failed: {result.diagnosis}", file=sys.stderr)
        return EXIT_SOLVE_FAILED
    return EXIT_OK
