"""``python -m benchmarks planner-latency``: the planner's guarantee, its price and its latency.

ROS-free, the controller's loop at real time (rtf 1): the parcels of a stream (``mixed`` by
default, its rate times ``--rate-factor``) reach the planner at their scan time, one after the
other (a parcel waits while the previous one is planned); each is planned with the deadline
the controller gives it (``Planner.deadline``) and planned again from the new time when its
stroke's start came too close meanwhile, as the node does. Every stroke planned is then run on
the plant, the scene's own settings with the exact parcel (``evaluate_stroke`` on the scene),
and checked against (8), (10)-(12). Per planner setting (the default; the same without the
uncertainty set; the stiff fence without it): parcels over each limit on the plant, declines
by reason and constraint, mean W_t (1) of the strokes, evaluations per parcel, planning
latency p50/p99 against the time to the deadline. Prints a table and writes ``--out``
(docs/reports/planner.md) and ``--json``; ``''`` writes nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import statistics
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

from fence_sorter.jsonsafe import json_safe
from fence_sorter.physics.params import ParameterError
from fence_sorter.verification.machine import git_revision

SCAN_X = -3.0
#: the controller's warm-up: parcels of the stream drawn with another seed, its time budget [s]
WARMUP_PARCELS, WARMUP_SEED, WARMUP_TIME = 400, 987654321, 8.0
#: the settings compared: name -> PlannerConfig fields over the defaults
SETTINGS = {
    "plant + uncertainty set (default)": {},
    "plant, mu1 and mu2 exact": dict(uncertainty_mu=0.0),
    "plant, exact figures": dict(uncertainty_mass=0.0, uncertainty_mu=0.0, uncertainty_size=0.0),
    "stiff fence, exact figures": dict(
        fence_model="stiff", uncertainty_mass=0.0, uncertainty_mu=0.0, uncertainty_size=0.0
    ),
}
LIMITS = (8, 10, 11, 12)


def register(parser: argparse.ArgumentParser) -> None:
    parser.description = "Planner latency against the deadline, and its strokes on the plant."
    parser.add_argument("--scene", default="impact_flexible")
    parser.add_argument("--belt-speed", type=float, default=2.0, metavar="M_S")
    parser.add_argument("--stream", default="mixed")
    parser.add_argument(
        "--rate-factor",
        default="2",
        metavar="X[,X...]",
        help="times the stream's own rate, one run each (default 2)",
    )
    parser.add_argument("--parcels", type=int, default=150, metavar="N")
    parser.add_argument(
        "--warmup-time",
        type=float,
        default=WARMUP_TIME,
        metavar="S",
        help=f"each planner's warm-up, as the controller's warmup_time (default {WARMUP_TIME:g})",
    )
    parser.add_argument("--out", default="docs/reports/planner.md", metavar="FILE")
    parser.add_argument("--json", default="docs/reports/planner.json", metavar="FILE")
    parser.set_defaults(func=run)


def _error(msg: str) -> int:
    print(f"benchmarks: error: {msg}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    try:
        factors = [float(x) for x in args.rate_factor.split(",")]
    except ValueError:
        factors = [math.nan]
    if not all(0.1 <= f <= 20.0 for f in factors):
        return _error(f"--rate-factor must be numbers in [0.1, 20], got {args.rate_factor!r}")
    if not 1 <= args.parcels <= 100000:
        return _error(f"--parcels must be in [1, 100000], got {args.parcels}")
    if not 0.0 <= args.warmup_time <= 600.0:
        return _error(f"--warmup-time must be in [0, 600] s, got {args.warmup_time:g}")
    if not 0.1 <= args.belt_speed <= 10.0:
        return _error(f"--belt-speed must be in [0.1, 10] m/s, got {args.belt_speed:g}")
    from fence_sorter.scene import SceneError, load_scene
    from fence_sorter.stream import StreamConfig, StreamError, generate

    try:
        base = load_scene(args.scene, [f"conveyor.belt_speed={args.belt_speed!r}"]).scenario
        cfg = StreamConfig.from_yaml(args.stream)
    except (SceneError, StreamError, ParameterError, OSError) as exc:
        return _error(str(exc))
    v = base.conveyor.belt_speed
    runs = []
    for factor in factors:
        c = replace(cfg, rate_pcs_h=cfg.rate_pcs_h * factor)
        stream = generate(c, v, count=args.parcels)
        warm = generate(c, v, count=WARMUP_PARCELS, seed=WARMUP_SEED)
        results = {}
        for name, fields in SETTINGS.items():
            results[name] = one_setting(base, stream, warm, fields, args.warmup_time)
            print_row(f"x{factor:g} {name}", results[name])
        runs.append({"rate_factor": factor, "rate_pcs_h": c.rate_pcs_h, "settings": results})
    data = {
        "command": (
            f"python -m benchmarks planner-latency --scene {shlex.quote(args.scene)} "
            f"--belt-speed {args.belt_speed:g} --stream {shlex.quote(args.stream)} "
            f"--rate-factor {','.join(f'{f:g}' for f in factors)} --parcels {args.parcels}"
            + (f" --warmup-time {args.warmup_time:g}" if args.warmup_time != WARMUP_TIME else "")
        ),
        "commit": git_revision(),
        "date": time.strftime("%Y-%m-%d", time.gmtime()),
        "cpus": os.cpu_count(),
        "load_average": os.getloadavg()[0],
        "belt_speed": v,
        "stream": args.stream,
        "runs": runs,
    }
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(json_safe(data), indent=1) + "\n")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(render(data))
    return 0


def one_setting(base, stream, warm, fields: dict, warmup_time: float = WARMUP_TIME) -> dict:
    """Plan the stream as the controller does at rtf 1, then run each stroke on the plant."""
    from fence_sorter.capacity import LoadRequest, Planner, PlannerConfig, evaluate_stroke

    planner = Planner(base, replace(PlannerConfig(), **fields))
    c = planner.config
    planner.warm_up([s.to_parcel_params() for s in warm[:1]], math.inf)  # the kernel
    planner.warm_up([s.to_parcel_params() for s in warm if s.divert], warmup_time)
    clock = 0.0  # sim time = wall time since the first scan (rtf 1)
    over: Counter[int] = Counter()
    declines: Counter[str] = Counter()
    latency, slack, ahead, evals, w_t = [], [], [], [], []
    worst = {"impact_speed": 0.0, "peak_accel": 0.0, "exit_speed": 0.0}
    planned = 0
    for s in stream:
        if not s.divert:
            continue
        planned += 1
        now = max(clock, s.arrival_time)  # the previous parcel's planning may have run late
        req = LoadRequest(s.parcel_id, s.to_parcel_params(), s.arrival_time, SCAN_X,
                          s.mu_belt, s.mu_fence)  # fmt: skip
        wall0 = time.perf_counter()
        deadline = planner.deadline(req, now, 1.0, wall0)
        plan = planner.plan(req, now, commit=False, deadline=deadline, rtf=1.0)
        n = plan.evaluations
        after = now + time.perf_counter() - wall0
        if plan.feasible and plan.start_time < after + c.start_margin:
            plan = planner.plan(req, after, commit=False, deadline=deadline, rtf=1.0)
            n += plan.evaluations
        done = time.perf_counter()
        clock = now + done - wall0
        latency.append(done - wall0)
        slack.append(deadline - done)
        ahead.append(deadline - wall0)
        evals.append(n)
        if not plan.feasible:
            declines[decline_key(plan)] += 1
            continue
        planner.busy_until = plan.end_time
        ev = plan.evaluation
        w_t.append(ev.capacity_pcs_h)
        got = evaluate_stroke(
            base, req.parcel, ev.r_s, ev.t1, c.alpha_k, c.profile, gap=c.pitch_gap,
            mu_belt=s.mu_belt, mu_fence=s.mu_fence,
        )  # fmt: skip
        for k in LIMITS:
            over[k] += int(k in got.violated)
        for k in worst:
            value = getattr(got, k)
            if math.isfinite(value):
                worst[k] = max(worst[k], value)
    q = statistics.quantiles(latency, n=100, method="inclusive") if len(latency) > 1 else []
    return {
        "config": fields,
        "parcels": planned,
        "strokes": len(w_t),
        "over_limit_on_plant": {str(k): over[k] for k in LIMITS},
        "worst_on_plant": worst,
        "declines": dict(sorted(declines.items())),
        "mean_W_t_pcs_h": statistics.fmean(w_t) if w_t else math.nan,
        "evaluations_per_parcel": statistics.fmean(evals) if evals else math.nan,
        "latency_p50_ms": 1e3 * statistics.median(latency) if latency else math.nan,
        "latency_p50_ms_evaluated": (
            1e3 * statistics.median(busy)
            if (busy := [t for t, n in zip(latency, evals, strict=True) if n])
            else math.nan
        ),
        "latency_p99_ms": 1e3 * q[98] if q else math.nan,
        "latency_max_ms": 1e3 * max(latency, default=math.nan),
        "time_to_deadline_median_ms": 1e3 * statistics.median(ahead) if ahead else math.nan,
        "time_to_deadline_min_ms": 1e3 * min(ahead, default=math.nan),
        "slack_min_ms": 1e3 * min(slack, default=math.nan),
    }


def decline_key(plan) -> str:
    """A decline's reason: too late / fence busy, the budget, or the failing constraints."""
    if plan.budget_ran_out:
        return "planning budget ran out"
    if not plan.tried:
        return plan.reason.split(":")[0].split(" until")[0]
    return "no feasible stroke: (" + ")+(".join(str(k) for k in plan.violated) + ")"


def print_row(name: str, r: dict) -> None:
    o = r["over_limit_on_plant"]
    print(
        f"{name}: {r['strokes']}/{r['parcels']} strokes, over on the plant (8) {o['8']} "
        f"(10) {o['10']} (11) {o['11']} (12) {o['12']}; mean W_t {r['mean_W_t_pcs_h']:.0f} "
        f"pcs/h; {r['evaluations_per_parcel']:.1f} evaluations/parcel; latency p50 "
        f"{r['latency_p50_ms']:.1f} ms ({r['latency_p50_ms_evaluated']:.1f} ms of those "
        f"evaluated), p99 {r['latency_p99_ms']:.1f} ms against "
        f"{r['time_to_deadline_median_ms']:.0f} ms to the deadline (median, min "
        f"{r['time_to_deadline_min_ms']:.0f}); declines {r['declines']}",
        flush=True,
    )


def render(data: dict) -> str:
    sections = []
    for run_ in data["runs"]:
        rows = []
        for name, r in run_["settings"].items():
            o = r["over_limit_on_plant"]
            w = r["worst_on_plant"]
            declines = ", ".join(f"{k}: {n}" for k, n in r["declines"].items()) or "none"
            rows.append(
                f"| {name} | {r['strokes']} / {r['parcels']} | {o['8']} | {o['10']} | {o['11']} "
                f"| {o['12']} | {w['impact_speed']:.2f} / {w['peak_accel']:.0f} / "
                f"{w['exit_speed']:.2f} | {r['mean_W_t_pcs_h']:.0f} "
                f"| {r['evaluations_per_parcel']:.1f} | {r['latency_p50_ms']:.1f} "
                f"({r['latency_p50_ms_evaluated']:.1f}) | {r['latency_p99_ms']:.1f} "
                f"| {r['time_to_deadline_median_ms']:.0f} ({r['time_to_deadline_min_ms']:.0f}) "
                f"| {declines} |"
            )
        sections.append(
            f"## {run_['rate_factor']:g}x the stream's rate: {run_['rate_pcs_h']:g} pcs/h\n\n"
            "| planner | strokes / parcels | over (8) | over (10) | over (11) | over (12) "
            "| worst on the plant | mean W_t [pcs/h] | evaluations / parcel "
            "| p50 (evaluated) [ms] | p99 [ms] | to the deadline, median (min) [ms] "
            "| declines |\n"
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n"
            + "\n".join(rows)
            + "\n"
        )
    first = next(iter(data["runs"][0]["settings"].values()))
    return (
        "# Planner: strokes on the plant, price and latency\n\n"
        f"`{data['command']}` at commit {data['commit']}, {data['date']}, on this machine "
        f"({data['cpus']} CPUs, shared; load average {data['load_average']:.2f} at the end; "
        "figures also in [planner.json](planner.json)).\n\n"
        f"The controller's loop without ROS at real time: {first['parcels']} parcels of the "
        f"`{data['stream']}` stream on a belt at {data['belt_speed']:g} m/s reach the planner "
        "at their scan time, one after the other; each is planned with its command's deadline "
        "(the front at R_s_max less start_margin, less deadline_margin; the time to it is that "
        "deadline less the parcel's turn, shorter when it waited for the one before), then "
        "its stroke is run on the plant (the scene's flexible fence at the scene's own solver "
        "settings, the exact parcel). Over: strokes whose plant run breaks (8) (not sorted), "
        "(10) w_n > 2.4 m/s, (11) a_N > 300 m/s^2 or (12) exit speed > 2.5 m/s (a plant run "
        "that failed counts over each). Worst: the "
        "largest w_n [m/s] / a_N [m/s^2] / exit speed [m/s] on the plant. Latency: wall time "
        "from the parcel's turn to its plan (re-plan included); p50 over every parcel and, in "
        "brackets, over those with at least one evaluation. W_t (1) is each stroke's own "
        "capacity; a single fence declines most parcels as fence busy at these rates.\n\n"
        + "\n".join(sections)
    )
