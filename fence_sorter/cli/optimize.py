"""``fence-sorter optimize``: the capacity optimum W_t (1) over X = [R_s, v, t1, R_z].

Exit codes: 0 an answer (an optimum, or ``"feasible": false`` with the constraint no point met),
2 bad arguments (one line naming the option and its allowed range). The sweeps behind the
paper's Figs. 3-10 run beside the package: ``python -m benchmarks paper-sweep``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from fence_sorter.jsonsafe import json_safe
from fence_sorter.optimize.problem import (
    BELT_WIDTH_RANGE,
    MASS_RANGE,
    MIN_LENGTH_LOW,
    MINIMAL_MASS,
    MINIMAL_SIZE,
    OptimizeSpec,
)
from fence_sorter.optimize.restarts import spread_lines
from fence_sorter.physics.params import ParameterError

EXIT_OK = 0
EXIT_BAD_INPUT = 2


def _constraints(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(c) for c in text.replace(" ", "").split(",") if c)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--constraints must be a comma-separated list of numbers from 7-12, got {text!r}"
        ) from None


def _bound(text: str) -> tuple[str, float, float]:
    try:
        name, rest = text.split("=", 1)
        lo, hi = (float(x) for x in rest.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--bound must be NAME=LOW:HIGH (NAME one of R_s, v, t1, R_z), got {text!r}"
        ) from None
    return name.strip(), lo, hi


def _fix(text: str) -> tuple[str, float]:
    try:
        name, value = text.split("=", 1)
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--fix must be NAME=VALUE (NAME one of R_s, v, t1, R_z), got {text!r}"
        ) from None


def _steps(text: str) -> dict[str, float]:
    out = {}
    for item in text.split(","):
        name, _, value = item.partition("=")
        try:
            step = float(value)
        except ValueError:
            step = math.nan
        if name.strip() not in ("R_s", "v", "t1", "R_z") or not (0.0 < step <= 10.0):
            raise argparse.ArgumentTypeError(
                f"--grid-steps must be NAME=STEP,... with NAME one of R_s, v, t1, R_z and STEP "
                f"in (0, 10], got {item!r}"
            )
        out[name.strip()] = step
    return out


def register(p: argparse.ArgumentParser) -> None:
    d = OptimizeSpec(case="positioned", alpha_k=0.7)
    p.description = (
        "Maximise the sorting capacity W_t (1) over X = [R_s, v, t1, R_z] within the ranges "
        "(3)-(6) subject to the selected constraints (7)-(12), evaluated on the twin "
        "(docs/guide/optimize.md). Prints the optimum X, W_t [pcs/h], Delta_c, the active "
        "constraints and every margin; 'feasible: false' with the constraint no point met."
    )
    p.add_argument(
        "--case", choices=("arbitrary", "positioned"), help="required: section 4.1 or 4.2"
    )
    p.add_argument(
        "--alpha-k",
        type=float,
        metavar="DEG",
        help="required: fence deflection alpha_k [deg], in (0, 89]",
    )
    p.add_argument("--w-dop", type=float, default=d.w_dop, help="(10) limit [m/s] (%(default)s)")
    p.add_argument(
        "--a-ndop", type=float, default=d.a_ndop, help="(11) limit [m/s^2] (%(default)s)"
    )
    p.add_argument(
        "--exit-speed-limit",
        type=float,
        default=d.exit_speed_limit,
        help="(12) limit ydot_dop [m/s] (%(default)s)",
    )
    p.add_argument(
        "--constraints",
        type=_constraints,
        default=None,
        metavar="LIST",
        help="constraints that count, e.g. 7,8,11 (default 7,8,9,10 arbitrary; 7,8,11 positioned)",
    )
    p.add_argument("--mu1", type=float, default=d.mu1, help="load-belt friction (%(default)s)")
    p.add_argument("--mu2", type=float, default=d.mu2, help="load-fence friction (%(default)s)")
    p.add_argument("--load-length", type=float, default=d.load_length, help="A [m] (%(default)s)")
    p.add_argument("--load-width", type=float, default=d.load_width, help="B [m] (%(default)s)")
    p.add_argument(
        "--mass",
        type=float,
        metavar="KG",
        default=d.mass,
        help=f"m_p of the limiting load A x B [kg], in [{MASS_RANGE[0]:g}, {MASS_RANGE[1]:g}] "
        f"(%(default)s; the minimal object of the arbitrary case keeps {MINIMAL_MASS:g} kg)",
    )
    p.add_argument(
        "--belt-width",
        type=float,
        metavar="M",
        default=d.belt_width,
        help=f"belt width s of (8) [m], in [{BELT_WIDTH_RANGE[0]:g}, {BELT_WIDTH_RANGE[1]:g}] "
        "(%(default)s); the arbitrary case's minimal object lies at Delta_s = s - 0.1 m",
    )
    p.add_argument(
        "--min-length",
        type=float,
        metavar="M",
        default=d.min_length,
        help=f"length along the belt of the arbitrary case's minimal object (0.1 m wide, the "
        f"T_g case of (9)) [m], in [{MIN_LENGTH_LOW:g}, max(A, {MINIMAL_SIZE:g})] (%(default)s)",
    )
    p.add_argument(
        "--gap", type=float, default=d.gap, help="Delta of (2), least gap [m] (%(default)s)"
    )
    p.add_argument(
        "--fix",
        type=_fix,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="hold a variable fixed within its range (3)-(6) or --bound, e.g. R_s=0 (repeatable)",
    )
    p.add_argument(
        "--bound",
        type=_bound,
        action="append",
        default=[],
        metavar="NAME=LOW:HIGH",
        help="override one of the ranges (3)-(6), e.g. v=0.2:2.0 (repeatable)",
    )
    p.add_argument("--fence", choices=("stiff", "flexible"), default=d.fence)
    p.add_argument(
        "--seed",
        type=int,
        default=d.seed,
        help="seed of the first restart; restart i runs with SEED+i (%(default)s)",
    )
    p.add_argument(
        "--budget",
        type=int,
        default=d.budget,
        help="max twin evaluations per restart (%(default)s)",
    )
    p.add_argument(
        "--restarts",
        type=int,
        default=d.restarts,
        help="independent searches (seeds SEED, SEED+1, ...); the best counts (%(default)s)",
    )
    p.add_argument("--workers", type=int, default=None, help="processes (default: CPU count)")
    p.add_argument(
        "--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler, e.g. tcp://h:8786"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--grid",
        action="store_true",
        help="instead of the optimiser, the exact best point of a regular grid (the yardstick "
        "of docs/design/optimize.md)",
    )
    p.add_argument(
        "--grid-steps",
        type=_steps,
        default=None,
        metavar="NAME=STEP,...",
        help="grid steps (default R_s=0.05,v=0.1,t1=0.05,R_z=0.025)",
    )
    p.set_defaults(func=run)


def error(message: str) -> int:
    print(f"fence-sorter optimize: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def spec_from_args(args: argparse.Namespace):
    """The validated OptimizeSpec of the command line (ParameterError names the option)."""
    if args.case is None:
        raise ParameterError("--case is required: one of arbitrary, positioned")
    if args.alpha_k is None:
        raise ParameterError("--alpha-k is required: the fence deflection in (0, 89] deg")
    if not (math.isfinite(args.alpha_k) and 0.0 < args.alpha_k <= 89.0):
        raise ParameterError(f"--alpha-k must be in (0, 89] deg, got {args.alpha_k!r}")
    constraints = args.constraints
    if constraints is None:
        constraints = (7, 8, 9, 10) if args.case == "arbitrary" else (7, 8, 11)
    spec = OptimizeSpec(
        case=args.case,
        alpha_k=math.radians(args.alpha_k),
        w_dop=args.w_dop,
        a_ndop=args.a_ndop,
        exit_speed_limit=args.exit_speed_limit,
        constraints=tuple(constraints),
        mu1=args.mu1,
        mu2=args.mu2,
        load_length=args.load_length,
        load_width=args.load_width,
        fixed=tuple(args.fix),
        bounds=tuple(args.bound),
        fence=args.fence,
        seed=args.seed,
        budget=args.budget,
        restarts=args.restarts,
        gap=args.gap,
        mass=args.mass,
        belt_width=args.belt_width,
        min_length=args.min_length,
    )
    try:
        return spec.validate()
    except ParameterError as exc:
        # name the option as typed: load_length -> --load-length
        msg = str(exc)
        for field in (
            "exit_speed_limit",
            "load_length",
            "load_width",
            "belt_width",
            "min_length",
            "w_dop",
            "a_ndop",
        ):
            if msg.startswith(field):
                msg = "--" + field.replace("_", "-") + msg[len(field) :]
                break
        else:
            if msg.split(" ", 1)[0] in (
                "mu1",
                "mu2",
                "gap",
                "mass",
                "seed",
                "budget",
                "restarts",
                "constraints",
            ):
                msg = "--" + msg
            elif msg.startswith("fixed."):
                name = msg[len("fixed.") :].split(" ", 1)[0]
                msg = f"--fix {msg[len('fixed.') :]}; widen the range with --bound {name}=LOW:HIGH"
            elif msg.startswith("fixed"):
                msg = "--fix " + msg
            elif msg.startswith("bounds"):
                msg = "--bound " + msg
        raise ParameterError(msg) from None


def header(spec: dict) -> str:
    """The problem's lines of a result: case, limits and the load model the twin ran."""
    head = (
        f"case {spec['case']}, alpha_k {spec['alpha_k_deg']:g} deg, constraints "
        f"{','.join(str(c) for c in spec['constraints'])}, fence {spec['fence']}"
    )
    loads = (
        f"limiting load A x B = {spec['load_length']:g} x {spec['load_width']:g} m, "
        f"m_p = {spec['mass']:g} kg, belt width s = {spec['belt_width']:g} m, "
        f"gap Delta = {spec['gap']:g} m"
    )
    if spec["case"] == "arbitrary":
        loads += (
            f"; minimal object {spec['min_length']:g} x {MINIMAL_SIZE:g} m, {MINIMAL_MASS:g} kg "
            f"at Delta_s = {spec['belt_width'] - MINIMAL_SIZE:g} m"
        )
    return f"{head}\n{loads}"


def summary(d: dict) -> str:
    """Readable lines of a result dict (OptimumResult.to_dict())."""
    head = header(d["spec"])
    tail = f"{d['evaluations']} twin evaluations, {d['wall_time']:.1f} s"
    if not d["feasible"]:
        return f"{head}\n{d['infeasible']}\n{tail}"
    x = d["X"]
    lines = [
        head,
        f"W_t = {d['W_t']:.0f} pcs/h, Delta_c = {d['Delta_c']:.3f} m",
        f"R_s = {x['R_s']:.3f} m, v = {x['v']:.3f} m/s, t1 = {x['t1']:.3f} s, "
        f"R_z = {x['R_z']:.3f} m",
        "active constraints: " + (", ".join(f"({c})" for c in d["active"]) or "none"),
        "margins: "
        + ", ".join(f"({c}) {m:.3g}" for c, m in d["margins"].items() if m is not None),
    ]
    if d.get("at_bounds"):
        lines.append(
            "at range bounds: " + ", ".join(f"{n} {s}" for n, s in d["at_bounds"].items())
        )
    optima = [math.nan if w is None else w for w in d.get("restarts") or ()]
    lines += spread_lines(d.get("restart_spread"), optima)
    lines.append(tail)
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    # lazy: loads the kernel (Numba), SciPy
    from fence_sorter.optimize.executor import evaluation_pool
    from fence_sorter.optimize.solve import grid_search, optimize

    try:
        spec = spec_from_args(args)
        if args.workers is not None and not 1 <= args.workers <= 1024:
            raise ParameterError(f"--workers must be in [1, 1024], got {args.workers}")
        with evaluation_pool(args.scheduler, args.workers) as executor:
            if args.grid:
                return _print_grid(grid_search(spec, args.grid_steps, executor), spec, args)
            result = optimize(spec, executor)
    except ParameterError as exc:
        return error(str(exc))
    d = result.to_dict()
    if args.json:
        print(json.dumps(d))
    else:
        print(summary(d))
    return EXIT_OK


def _print_grid(g: dict, spec, args) -> int:
    best = g["best"]
    d = {
        "feasible": best is not None,
        "X": best["X"] if best else {},
        "W_t": best["W_t"] if best else math.nan,
        "Delta_c": best["Delta_c"] if best else math.nan,
        "margins": {c: best["margins"].get(c, math.nan) for c in spec.constraints} if best else {},
        "grid_points": g["grid_points"],
        "steps": g["steps"],
        "evaluations": g["evaluations"],
        "wall_time": g["wall_time"],
        "spec": spec.to_dict(),
    }
    if args.json:
        print(json.dumps(json_safe(d)))
        return EXIT_OK
    steps = ", ".join(f"{n} {s:g}" for n, s in g["steps"].items())
    print(header(d["spec"]))
    print(
        f"grid of {g['grid_points']} points (steps {steps}), {g['evaluations']} simulated, "
        f"{g['wall_time']:.1f} s"
    )
    if best is None:
        print("no feasible grid point")
    else:
        x = best["X"]
        print(
            f"best W_t = {best['W_t']:.0f} pcs/h at R_s = {x['R_s']:.3f} m, v = {x['v']:.3f} m/s, "
            f"t1 = {x['t1']:.3f} s, R_z = {x['R_z']:.3f} m"
        )
    return EXIT_OK
