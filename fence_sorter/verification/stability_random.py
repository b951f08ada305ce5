"""Random stability campaign: sorting events drawn over the space a user reaches, each solved once.

Event i of seed S is drawn from its own generator (``numpy.random.default_rng([S, i])``), so any
event is reproduced from (S, i) alone, whatever the campaign's size or worker count. The space
(:data:`SPACE`) is the documented one: loads of mass 0.5-30 kg and sides A, B of 0.1-0.7 m,
yawed up to 10 deg, that fit the 0.7 m belt with a lateral gap Delta_s >= 0, their C_s anywhere
in the rectangle (offsets up to half its sides); belt speed 0.5-2.5 m/s; strokes from the
planner's candidate grid (R_s -0.4-1.0 m in 0.2 m, t1 0.2-1.5 s in 0.1 s) at alpha_k 30, 40 or
50 deg; the stiff fence or the flexible PA6 fence of the default scene (impact_flexible), solved
with the scene's settings (the plant) or the planner's looser ones (``capacity.evaluate``).

An event fails when its solve stops with a diagnosis (deep penetration, runaway speed, step
below min_dt, non-finite state, wall-time limit) or raises; the campaign counts the failures by
cause and bounds the region of each cause (every drawn parameter's range over its failures).
``python -m benchmarks stability-random`` runs it on the evaluation pool and writes
docs/reports/stability/random.md and random.json (the markdown from the JSON alone).
"""

from __future__ import annotations

import functools
import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np

from fence_sorter.capacity.evaluate import planning_scenario
from fence_sorter.physics.params import DriveParams, ParcelParams
from fence_sorter.physics.simulate import Scenario, SortingModel, solve_stepper
from fence_sorter.physics.stepper import run
from fence_sorter.pool import evaluation_pool
from fence_sorter.scene import load_scene
from fence_sorter.verification.report import table

#: the scene whose conveyor, fence, contact and solver every event starts from
BASE_SCENE = "impact_flexible"


@dataclass(frozen=True)
class Space:
    """The ranges events are drawn from (SI units; angles in degrees, as a user gives them)."""

    mass: tuple[float, float] = (0.5, 30.0)  # m_p [kg]
    side: tuple[float, float] = (0.1, 0.7)  # A and B [m]
    belt_speed: tuple[float, float] = (0.5, 2.5)  # [m/s]
    yaw_deg: float = 10.0  # |phi| <= this [deg]
    belt_width: float = 0.7  # s [m]: lateral gap + footprint width fit on it
    r_s: tuple[float, float, float] = (-0.4, 1.0, 0.2)  # the planner's grid: first, last, step
    t1: tuple[float, float, float] = (0.2, 1.5, 0.1)
    alpha_k_deg: tuple[float, ...] = (30.0, 40.0, 50.0)
    fences: tuple[str, ...] = ("stiff", "flexible")
    solvers: tuple[str, ...] = ("scene", "planning")


SPACE = Space()


def _grid(first: float, last: float, step: float) -> list[float]:
    n = int(math.floor((last - first) / step + 1e-9))
    return [round(first + i * step, 9) for i in range(n + 1)]


@dataclass(frozen=True)
class Event:
    """One drawn sorting event: the load, the belt, the stroke, the fence and the settings."""

    seed: int
    index: int
    mass: float
    length_a: float
    width_b: float
    yaw_deg: float
    lateral_gap: float
    cog_x: float  # x_p [m]
    cog_y: float  # y_p [m]
    belt_speed: float
    r_s: float
    t1: float
    alpha_k_deg: float
    fence: str  # stiff | flexible
    solver: str  # scene | planning

    def parcel(self) -> ParcelParams:
        return ParcelParams(
            length_a=self.length_a,
            width_b=self.width_b,
            height=0.2,
            mass=self.mass,
            cog_offset_x=self.cog_x,
            cog_offset_y=self.cog_y,
            lateral_gap=self.lateral_gap,
            yaw=math.radians(self.yaw_deg),
        )


def draw_event(seed: int, index: int, space: Space = SPACE) -> Event:
    """Event ``index`` of campaign ``seed``: uniform over the space; A, B and the yaw drawn
    again until the yawed footprint fits the belt, then Delta_s uniform over the room left."""
    rng = np.random.default_rng([seed, index])
    while True:
        a, b = (float(v) for v in rng.uniform(*space.side, size=2))
        yaw = float(rng.uniform(-space.yaw_deg, space.yaw_deg))
        c, s = abs(math.cos(math.radians(yaw))), abs(math.sin(math.radians(yaw)))
        footprint = a * s + b * c
        if footprint <= space.belt_width:
            break
    return Event(
        seed=seed,
        index=index,
        mass=float(rng.uniform(*space.mass)),
        length_a=a,
        width_b=b,
        yaw_deg=yaw,
        lateral_gap=float(rng.uniform(0.0, space.belt_width - footprint)),
        cog_x=float(rng.uniform(-0.5 * a, 0.5 * a)),
        cog_y=float(rng.uniform(-0.5 * b, 0.5 * b)),
        belt_speed=float(rng.uniform(*space.belt_speed)),
        r_s=float(rng.choice(_grid(*space.r_s))),
        t1=float(rng.choice(_grid(*space.t1))),
        alpha_k_deg=float(rng.choice(space.alpha_k_deg)),
        fence=str(rng.choice(space.fences)),
        solver=str(rng.choice(space.solvers)),
    )


@functools.lru_cache(maxsize=1)
def base_scenario() -> Scenario:
    """The default scene, nothing recorded."""
    return replace(load_scene(BASE_SCENE).scenario, record=())


def scenario_of(ev: Event) -> Scenario:
    """The scenario of an event on the base scene (its fence stiff or flexible, the scene's or
    the planner's solver settings)."""
    sc = base_scenario()
    drive = DriveParams(alpha_k=math.radians(ev.alpha_k_deg), t1=ev.t1, r_s=ev.r_s)
    sc = replace(
        sc,
        conveyor=replace(sc.conveyor, belt_speed=ev.belt_speed),
        parcel=ev.parcel(),
        drive=drive,
    )
    if ev.fence == "stiff":
        sc = replace(sc, fence=None, fence_length=sc.length, fence_modes=None)
    if ev.solver == "planning":
        sc = planning_scenario(sc, fence="scene")
    return sc


def run_event(ev: Event) -> dict:
    """Solve one event: its parameters, whether it failed and why, and its figures."""
    out = asdict(ev)
    wall0 = time.perf_counter()
    try:
        sc = scenario_of(ev)
        model = SortingModel(sc)
        stepper = solve_stepper(model)
        r = run(stepper)
    except Exception as exc:  # a crash is a bug: counted as a failure of its own cause
        out.update(cause="exception", diagnosis=f"{type(exc).__name__}: {exc}", sorted=False)
        out.update(d_max=math.nan, d_ratio=math.nan, peak_n=math.nan, wall=0.0)
        out.update(w_n=math.nan, d_law_ratio=math.nan)
        return out
    diag = stepper.diagnosis
    w_n = max((float(w) for _, w, _ in r.impacts), default=0.0)  # the fastest impact's
    # law (16) with b = 0: D_max = (5 m w_n^2 / (2 k_p))^(1/5) of a free impact at w_n
    d_law = (5.0 * ev.mass * w_n**2 / (2.0 * sc.contact.k_p)) ** 0.2 if w_n > 0 else 0.0
    out.update(
        cause=None if diag is None else diag.kind.value,
        diagnosis=r.diagnosis,
        sorted=bool(r.sorted),
        d_max=float(r.max_penetration),
        d_ratio=float(r.max_penetration / model.deep),
        peak_n=float(r.peak_contact_force),
        w_n=w_n,
        d_law_ratio=d_law / model.deep if math.isfinite(d_law) else math.nan,
        wall=time.perf_counter() - wall0,
    )
    return out


def run_chunk(seed: int, indices: Sequence[int]) -> list[dict]:
    """Draw and solve the events ``indices`` of ``seed`` (one task of the pool)."""
    return [run_event(draw_event(seed, i)) for i in indices]


def warm_up() -> None:
    """Compile the kernel and load the base scene before the pool forks (both fences)."""
    for i in range(4):
        run_event(replace(draw_event(0, i), fence=SPACE.fences[i % 2], t1=0.2))


def run_campaign(
    events: int,
    seed: int,
    *,
    workers: int | None = None,
    chunk: int = 50,
    progress: Callable[[int, int], None] | None = None,
) -> list[dict]:
    """Events 0 .. events-1 of ``seed`` on the evaluation pool (``fence_sorter.pool``), in
    their order; ``progress(done, failed)`` after each chunk."""
    chunks = [range(i, min(i + chunk, events)) for i in range(0, events, chunk)]
    out: list[dict] = []
    failed = 0
    with evaluation_pool(workers=workers, warm_up=warm_up) as pool:
        futures = [pool.submit(run_chunk, seed, list(c)) for c in chunks]
        for fut in futures:
            part = fut.result()
            out.extend(part)
            failed += sum(1 for o in part if o["cause"] is not None)
            if progress is not None:
                progress(len(out), failed)
    return out


# -- the summary -----------------------------------------------------------------------------
#: the drawn parameters whose range over the failures bounds a failing region
REGION = (
    "mass", "length_a", "width_b", "yaw_deg", "lateral_gap", "cog_x", "cog_y", "belt_speed",
    "r_s", "t1", "alpha_k_deg", "w_n", "d_law_ratio",
)  # fmt: skip
UNITS = {
    "mass": "kg", "length_a": "m", "width_b": "m", "yaw_deg": "deg", "lateral_gap": "m",
    "cog_x": "m", "cog_y": "m", "belt_speed": "m/s", "r_s": "m", "t1": "s", "alpha_k_deg": "deg",
    "w_n": "m/s", "d_law_ratio": "-",
}  # fmt: skip


#: the columns of a failing region's table of events
EVENT_COLUMNS = (
    "index", "fence", "solver", "mass", "length_a", "width_b", "belt_speed", "r_s", "t1",
    "alpha_k_deg", "w_n", "d_law_ratio", "d_ratio",
)  # fmt: skip


def _range(values) -> list:
    """[min, max] of the finite values ([None, None] if none)."""
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return [min(vals), max(vals)] if vals else [None, None]


def _finite_max(values) -> float | None:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return max(vals) if vals else None


def summarise(outcomes: Sequence[dict]) -> dict:
    """Counts (events, solved, sorted, failures by cause and by fence / settings), the largest
    D / deep-penetration limit and peak N of the solved events, wall time per event, and per
    failure cause the range of every drawn parameter over its events plus the events."""
    causes = Counter(o["cause"] for o in outcomes if o["cause"] is not None)
    by_kind = Counter(f"{o['fence']}/{o['solver']}" for o in outcomes if o["cause"] is not None)
    drawn = Counter(f"{o['fence']}/{o['solver']}" for o in outcomes)
    solved = [o for o in outcomes if o["cause"] is None]
    regions = {}
    for cause in sorted(causes):
        bad = [o for o in outcomes if o["cause"] == cause]
        regions[cause] = {
            "events": len(bad),
            "bounds": {k: _range(o[k] for o in bad) for k in REGION},
            "fences": sorted({o["fence"] for o in bad}),
            "solvers": sorted({o["solver"] for o in bad}),
            "indices": [o["index"] for o in bad][:50],
            "diagnoses": [o["diagnosis"] for o in bad][:10],
            "rows": [{k: o[k] for k in EVENT_COLUMNS} for o in bad][:50],
        }
    walls = [o["wall"] for o in outcomes]
    return {
        "events": len(outcomes),
        "solved": len(solved),
        "sorted": sum(1 for o in solved if o["sorted"]),
        "failures": sum(causes.values()),
        "failures_by_cause": dict(sorted(causes.items())),
        "drawn_by_fence_solver": dict(sorted(drawn.items())),
        "failures_by_fence_solver": dict(sorted(by_kind.items())),
        "max_d_ratio": _finite_max(o["d_ratio"] for o in solved),
        "max_d": _finite_max(o["d_max"] for o in solved),
        "max_peak_n": _finite_max(o["peak_n"] for o in solved),
        "mean_wall_s": float(np.mean(walls)) if walls else None,
        "max_wall_s": max(walls) if walls else None,
        "regions": regions,
    }


def results_json(outcomes: Sequence[dict], seed: int, meta: dict) -> dict:
    """The report's data: the run's meta, the space, the summary (the events themselves are
    reproduced from (seed, index))."""
    return {**meta, "seed": seed, "space": asdict(SPACE), "summary": summarise(outcomes)}


def _g(v) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float) and not math.isfinite(v):
        return "n/a"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def render_markdown(data: dict) -> str:
    """random.md from random.json."""
    s = data["summary"]
    sp = data["space"]
    mi = data["machine"]
    lines = [
        "# Random stability campaign",
        "",
        "Generated by `python -m benchmarks stability-random` "
        "(`fence_sorter/verification/stability_random.py`) from `random.json`; do not edit by "
        "hand. Event i of seed S is drawn from its own generator, so `draw_event(S, i)` "
        "reproduces any event alone.",
        "",
        f"- command: `{data['command']}`",
        f"- date: {data['date']}, commit {data['commit']}",
        f"- machine: {mi['cpu']}, {mi['cores']} cores, {mi['os']}; Python {mi['python']}, "
        f"NumPy {mi['numpy']}, SciPy {mi['scipy']}, Numba {mi['numba']}",
        f"- wall time: {_g(data['wall_time_s'])} s on {data['workers']} worker(s)",
        "",
        "## Space",
        "",
    ]
    space_rows = [
        ["mass m_p", f"{sp['mass'][0]:g}-{sp['mass'][1]:g} kg, uniform"],
        ["sides A, B", f"{sp['side'][0]:g}-{sp['side'][1]:g} m, uniform; drawn again until "
         f"the yawed footprint fits the {sp['belt_width']:g} m belt"],
        ["yaw", f"+-{sp['yaw_deg']:g} deg, uniform"],
        ["lateral gap Delta_s", "uniform over the room the footprint leaves on the belt"],
        ["C_s offsets x_p, y_p", "uniform up to +-A/2, +-B/2"],
        ["belt speed", f"{sp['belt_speed'][0]:g}-{sp['belt_speed'][1]:g} m/s, uniform"],
        ["R_s", f"{sp['r_s'][0]:g}-{sp['r_s'][1]:g} m in {sp['r_s'][2]:g} m (planner's grid)"],
        ["t1", f"{sp['t1'][0]:g}-{sp['t1'][1]:g} s in {sp['t1'][2]:g} s (planner's grid)"],
        ["alpha_k", ", ".join(f"{a:g}" for a in sp["alpha_k_deg"]) + " deg"],
        ["fence", " or ".join(sp["fences"]) + f" ({BASE_SCENE}'s PA6 fence when flexible)"],
        ["solver settings", "the scene's (the plant) or the planner's (capacity.evaluate)"],
    ]  # fmt: skip
    lines += table(["parameter", "drawn"], space_rows)
    lines += ["", "## Results", ""]
    rows = [
        ["events", s["events"]],
        ["solved", s["solved"]],
        ["sorted", s["sorted"]],
        ["solver failures", s["failures"]],
        ["failures by cause", ", ".join(f"{k}: {v}" for k, v in s["failures_by_cause"].items())
         or "none"],
        ["events by fence/settings", ", ".join(
            f"{k}: {v}" for k, v in s["drawn_by_fence_solver"].items())],
        ["failures by fence/settings", ", ".join(
            f"{k}: {v}" for k, v in s["failures_by_fence_solver"].items()) or "none"],
        ["largest D / deep-penetration limit (solved)", _g(s["max_d_ratio"])],
        ["largest D [m] (solved)", _g(s["max_d"])],
        ["largest peak N [N] (solved)", _g(s["max_peak_n"])],
        ["wall per event, mean / max [s]", f"{_g(s['mean_wall_s'])} / {_g(s['max_wall_s'])}"],
    ]  # fmt: skip
    lines += table(["figure", "value"], rows)
    for cause, reg in s["regions"].items():
        lines += ["", f"## Failing region: {cause} ({reg['events']} events)", ""]
        lines += table(
            ["parameter", "min", "max"],
            [[f"{k} [{UNITS[k]}]", _g(lo), _g(hi)] for k, (lo, hi) in reg["bounds"].items()]
            + [
                ["fence", ", ".join(reg["fences"]), ""],
                ["settings", ", ".join(reg["solvers"]), ""],
            ],
        )
        lines += ["", "Events (seed, index): " + ", ".join(
            f"({data['seed']}, {i})" for i in reg["indices"])]  # fmt: skip
        lines += [
            "",
            "Per event: the fastest impact's w_n, the law (16) free-impact D_max at it over the "
            "deep-penetration limit (above 1: the law's own penetration is past the limit) and "
            "the failing D over the limit.",
            "",
        ]
        lines += table(
            ["index", "fence", "settings", "m [kg]", "A x B [m]", "v [m/s]", "R_s [m]", "t1 [s]",
             "alpha_k [deg]", "w_n [m/s]", "D_law / limit", "D / limit"],
            [[r["index"], r["fence"], r["solver"], _g(r["mass"]),
              f"{_g(r['length_a'])} x {_g(r['width_b'])}", _g(r["belt_speed"]), _g(r["r_s"]),
              _g(r["t1"]), _g(r["alpha_k_deg"]), _g(r["w_n"]), _g(r["d_law_ratio"]),
              _g(r["d_ratio"])] for r in reg.get("rows", [])],
        )  # fmt: skip
        lines += [""] + [f"- {d}" for d in reg["diagnoses"]]
    return "\n".join(lines) + "\n"
