"""Work-precision diagrams: error against wall time for every integration method.

For each benchmark scene and each method over a range of step sizes (fixed-step methods) or
tolerances (adaptive and the SciPy baselines), one solve is compared with a reference solution of
the same scene and timed. The result is a table per scene and log-log plots of error against wall
time, one curve per method, with the scene's default configuration as a marked point.

Reference. Our ``trapezoidal`` at a fixed step of 2 ms / 512 (``REF_DT``), its contact iteration
converged to 1e-12 (``REF_TOLERANCE``; the default 1e-9 would floor it): second order with the
model's discontinuities located, it reaches a converged solution at a bounded cost (no error
estimator to trust, no tolerance-to-error mapping). It is checked three ways, each reported:

- its halved-step twin (same scheme at ``REF_DT / 2``): the difference estimates the reference's
  own error (for a second-order scheme the reference error is about 4/3 of it);
- ``generalized_alpha`` at ``REF_DT``: an independent time discretisation of the same model;
- a SciPy solver at a tight tolerance (``ODE_REFERENCE``) on the ODE form of the model
  (``kernel.rhs``, explicit Karnopp friction): the converged answer of the SciPy baselines. Where
  it differs from the reference by more than the reference's own error, the two forms of the
  model differ, and no SciPy run can be more accurate than that difference; the plots draw it as
  the SciPy floor and the tables add each SciPy run's peak-force error against it.

Error measures (``error_measures``), each against the reference:

- ``peak_force``: |N_peak - N_ref| / N_ref, N_peak the run's largest summed fence normal force
  over its accepted points;
- ``trajectory``: RMS over a 1 ms grid on the common time span of the distance between the run's
  and the reference's C_s, both interpolated by cubic Hermite splines through the accepted
  points' positions and velocities;
- ``trajectory_to_sort``: the same up to the reference's sort crossing, for a scene that runs on
  after it (there the load leaves the belt, and the rest of the run carries the velocity error
  made at that switch);
- ``tip_deflection``: RMS on the same grid of the fence tip deflection difference (linear
  interpolation between accepted points); flexible fences only;
- ``final_pose``: the largest displacement of a load corner between the run's and the
  reference's pose (x, y, phi) at the common end time (the sort crossing, give or take a step,
  for a scene that stops when sorted).

Timing: one untimed warm-up solve per scene and method (the Numba kernel compiles or loads on
first use), then the median of ``repeats`` ``time.perf_counter()`` wall times of ``simulate()``
(one for a solve longer than ``LONG_RUN`` s). A solve stopped by ``solver.max_wall_time`` is
reported as capped, with no error point, and the method's tighter settings are skipped.
"""

from __future__ import annotations

import json
import math
import statistics
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from fence_sorter.jsonsafe import json_safe
from fence_sorter.physics.params import OUR_METHODS, SCIPY_METHODS
from fence_sorter.physics.simulate import Scenario, SimulationResult, SortingModel, simulate
from fence_sorter.scene import load_scene
from fence_sorter.verification import machine
from fence_sorter.verification.report import table

SCENES = ("impact_flexible", "slide_flexible", "positioned_stiff", "arbitrary_stiff")
METHODS = OUR_METHODS + SCIPY_METHODS
RECORD = ("trajectory", "fence", "forces")
MEASURES = ("peak_force", "trajectory", "trajectory_to_sort", "tip_deflection", "final_pose")
MEASURE_TEXT = {
    "peak_force": ("peak contact force", "relative error |N_peak - N_ref| / N_ref"),
    "trajectory": ("trajectory of C_s", "RMS position error [m]"),
    "trajectory_to_sort": ("trajectory up to the sort", "RMS position error until sorted [m]"),
    "tip_deflection": ("fence tip deflection", "RMS error [m]"),
    "final_pose": ("final pose", "largest corner displacement [m]"),
}
GRID_STEP = 1e-3  # [s] the grid of the RMS measures
ATOL_PER_RTOL = 1e-2  # atol = 1e-2 rtol (the default rtol 1e-4, atol 1e-6 keep this ratio)
FIXED_DTS = tuple(2e-3 / 2**k for k in range(7))  # 2 ms ... 31.25 us, halving
ADAPTIVE_RTOLS = tuple(10.0**-k for k in range(2, 9))  # 1e-2 ... 1e-8
SCIPY_RTOLS = tuple(10.0**-k for k in range(3, 9))  # 1e-3 ... 1e-8
REF_DT = 2e-3 / 512  # 3.90625 us
REF_DT_QUICK = 2e-3 / 256  # 7.8125 us: 4x below the quick runs' smallest final-pose error
# the reference's contact iteration tolerance [m, m/s]: the default 1e-9 would put a floor of a
# few 1e-9 m under the reference's trajectory (its halved-step check shows it)
REF_TOLERANCE = 1e-12
REF_MAX_ITERATIONS = 30
ODE_REFERENCE = {  # scene -> (SciPy method, rtol) of the ODE-form reference
    "impact_flexible": ("scipy:Radau", 1e-9),
    "slide_flexible": ("scipy:Radau", 1e-9),
    "positioned_stiff": ("scipy:DOP853", 1e-10),
    "arbitrary_stiff": ("scipy:RK45", 1e-6),  # the ODE form's stick phase near 0.573 s
    # costs the explicit and implicit solvers a great many steps; RK45 at 1e-7 takes ~80 s
}
ODE_REFERENCE_DEFAULT = ("scipy:Radau", 1e-9)
ODE_TWIN_WALL = 240.0  # [s] cap of the ODE-form reference's tenfold-tighter check
QUICK_SCENES = ("positioned_stiff",)
QUICK_METHODS = ("adaptive", "trapezoidal", "generalized_alpha", "scipy:RK45", "scipy:LSODA")
QUICK_GRID = {
    "adaptive": (1e-3, 1e-5),
    "trapezoidal": (1e-3, 5e-4, 2.5e-4),
    "generalized_alpha": (1e-3, 5e-4, 2.5e-4),
}
QUICK_SCIPY_RTOLS = (1e-3, 1e-5)
LONG_RUN = 5.0  # [s] a solve this long is timed once
WARMUP_WALL = 10.0  # [s] cap of the untimed warm-up solve
MARKERS = {
    "adaptive": "o",
    "trapezoidal": "s",
    "generalized_alpha": "D",
    "scipy:RK45": "v",
    "scipy:DOP853": "^",
    "scipy:Radau": "<",
    "scipy:BDF": ">",
    "scipy:LSODA": "P",
}

Progress = Callable[[str], None]


def _quiet(_: str) -> None:
    pass


# -- settings -----------------------------------------------------------------------------------
def setting_name(method: str) -> str:
    """``dt`` for the fixed-step methods, ``rtol`` for the error-controlled ones."""
    return "dt" if method in ("trapezoidal", "generalized_alpha") else "rtol"


def grid(method: str, quick: bool = False) -> tuple[float, ...]:
    """The settings one method is run at, loosest first."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; one of {', '.join(METHODS)}")
    if quick:
        return QUICK_GRID.get(method, QUICK_SCIPY_RTOLS)
    if setting_name(method) == "dt":
        return FIXED_DTS
    return ADAPTIVE_RTOLS if method == "adaptive" else SCIPY_RTOLS


def configure(sc: Scenario, method: str, value: float, max_wall: float) -> Scenario:
    """The scene ``sc`` solved by ``method`` at ``value`` (dt or rtol), recording RECORD."""
    sv = sc.solver
    if setting_name(method) == "dt":
        sv = replace(sv, method=method, dt=value, min_dt=min(sv.min_dt, value))
    else:
        sv = replace(sv, method=method, rtol=value, atol=value * ATOL_PER_RTOL)
    sv = replace(sv, max_wall_time=max_wall)
    sv.validate()
    return replace(sc, solver=sv, record=RECORD)


def describe(method: str, value: float) -> str:
    unit = " s" if setting_name(method) == "dt" else ""
    return f"{method} {setting_name(method)} = {value:.4g}{unit}"


# -- traces and error measures ------------------------------------------------------------------
def _increasing(t: np.ndarray) -> np.ndarray:
    """Mask keeping each time strictly later than all before it (drops duplicate event times)."""
    t = np.asarray(t, dtype=float)
    if len(t) == 0:
        return np.zeros(0, dtype=bool)
    keep = np.ones(len(t), dtype=bool)
    keep[1:] = t[1:] > np.maximum.accumulate(t)[:-1]
    return keep


class Trace:
    """A run's recorded series as functions of time (Hermite for the load, linear for the tip)."""

    def __init__(self, result: SimulationResult):
        s = result.series
        keep = _increasing(s["t"])
        t = np.asarray(s["t"], dtype=float)[keep]
        if len(t) < 2:
            raise ValueError("fewer than two recorded points")
        self.t_end = float(t[-1])
        self.peak = float(result.peak_contact_force)
        self.sim_time = float(result.sim_time)

        def spline(key: str, rate: str) -> CubicHermiteSpline:
            return CubicHermiteSpline(
                t, np.asarray(s[key], dtype=float)[keep], np.asarray(s[rate], dtype=float)[keep]
            )

        self.x = spline("x", "vx")
        self.y = spline("y", "vy")
        self.phi = spline("phi", "phidot")
        self.tip_t = self.tip = None
        if "tip_deflection" in s and "fem_fence" in result.model_parts:
            kf = _increasing(s["t_fence"])
            self.tip_t = np.asarray(s["t_fence"], dtype=float)[kf]
            self.tip = np.asarray(s["tip_deflection"], dtype=float)[kf]

    def pose(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.x(t), self.y(t), self.phi(t)

    def tip_at(self, t) -> np.ndarray | None:
        return None if self.tip is None else np.interp(t, self.tip_t, self.tip)


@dataclass
class ReferenceSolution:
    """One converged solve of a scene: its trace and what the measures need."""

    label: str
    method: str
    value: float
    trace: Trace
    corners: np.ndarray  # load corners relative to C_s [m]
    flexible: bool
    peak: float
    sim_time: float
    steps: int
    wall: float
    t_sorted: float = math.nan  # first accepted point past y0 = s; NaN if not sorted

    @property
    def runs_on_after_sort(self) -> bool:
        return math.isfinite(self.t_sorted) and self.trace.t_end > self.t_sorted + 10 * GRID_STEP


def error_measures(result: SimulationResult, ref: ReferenceSolution) -> dict[str, float]:
    """The four error measures of ``result`` against ``ref`` (NaN where one does not apply)."""
    tr = Trace(result)
    rt = ref.trace
    t_c = min(tr.t_end, rt.t_end)
    g = np.arange(0.0, t_c, GRID_STEP)
    errors = {m: math.nan for m in MEASURES}
    errors["peak_force"] = abs(tr.peak - rt.peak) / rt.peak if rt.peak > 0 else math.nan
    xa, ya, _ = tr.pose(g)
    xb, yb, _ = rt.pose(g)
    d2 = (xa - xb) ** 2 + (ya - yb) ** 2
    errors["trajectory"] = float(np.sqrt(np.mean(d2)))
    if ref.runs_on_after_sort:
        errors["trajectory_to_sort"] = float(np.sqrt(np.mean(d2[g < ref.t_sorted])))
    if ref.flexible and tr.tip is not None and rt.tip is not None:
        errors["tip_deflection"] = float(np.sqrt(np.mean((tr.tip_at(g) - rt.tip_at(g)) ** 2)))
    pa = [float(v) for v in tr.pose(t_c)]
    pb = [float(v) for v in rt.pose(t_c)]
    errors["final_pose"] = corner_displacement(pa, pb, ref.corners)
    return errors


def corner_displacement(pa: Sequence[float], pb: Sequence[float], corners: np.ndarray) -> float:
    """Largest distance between the same load corner in poses ``pa`` and ``pb`` (x, y, phi)."""

    def place(p):
        c, s = math.cos(p[2]), math.sin(p[2])
        return np.column_stack(
            (
                p[0] + c * corners[:, 0] - s * corners[:, 1],
                p[1] + s * corners[:, 0] + c * corners[:, 1],
            )
        )

    return float(np.max(np.hypot(*(place(pa) - place(pb)).T)))


# -- runs -------------------------------------------------------------------------------------
@dataclass
class RunPoint:
    """One (scene, method, setting) of the campaign."""

    scene: str
    method: str
    setting: str  # "dt" or "rtol"
    value: float
    status: str  # ok | capped | failed | skipped
    wall: float = math.nan  # median wall time [s]
    walls: list[float] = field(default_factory=list)
    sim_time: float = math.nan
    steps: int = 0
    rejected: int = 0
    errors: dict[str, float] = field(default_factory=dict)
    errors_ode: dict[str, float] = field(default_factory=dict)  # SciPy runs: vs the ODE form
    is_default: bool = False
    note: str = ""
    peak: float = math.nan
    sorted: bool = False

    @property
    def rtf(self) -> float:
        """Real-time factor: simulated time over wall time."""
        return self.sim_time / self.wall if self.wall > 0 else math.nan

    @property
    def label(self) -> str:
        return "default" if self.is_default else self.method


def _status(result: SimulationResult) -> str:
    if result.diagnosis is None:
        return "ok"
    if result.diagnosis.startswith("wall-time limit"):
        return "capped"
    return "failed"


def timed(sc: Scenario) -> tuple[SimulationResult, float]:
    """One solve and its wall time (perf_counter around ``simulate``)."""
    t0 = time.perf_counter()
    result = simulate(sc)
    return result, time.perf_counter() - t0


def measure(
    scene: str,
    sc: Scenario,
    ref: Reference,
    repeats: int,
    *,
    is_default: bool = False,
) -> RunPoint:
    """Solve ``sc`` (median of ``repeats`` timed runs) and compare it with the reference."""
    sv = sc.solver
    method = sv.method
    name = setting_name(method)
    value = sv.dt if name == "dt" else sv.rtol
    result, wall = timed(sc)
    walls = [wall]
    status = _status(result)
    point = RunPoint(
        scene,
        method,
        name,
        value,
        status,
        is_default=is_default,
        sim_time=result.sim_time,
        steps=result.steps,
        rejected=result.rejected_steps,
        peak=result.peak_contact_force,
        sorted=result.sorted,
    )
    if status == "ok":
        point.errors = error_measures(result, ref.main)
        if method in SCIPY_METHODS and ref.ode is not None:
            point.errors_ode = error_measures(result, ref.ode)
        if result.forced_steps:
            point.note = f"{result.forced_steps} forced steps"
    else:
        point.note = result.diagnosis or ""
    del result
    if status == "ok" and wall <= LONG_RUN:
        for _ in range(repeats - 1):
            walls.append(timed(sc)[1])
    point.walls = walls
    point.wall = statistics.median(walls)
    return point


# -- reference ----------------------------------------------------------------------------------
@dataclass
class ReferenceCheck:
    """A second solve compared with the reference: its differences are the reference's error."""

    label: str
    kind: str  # "twin" (halved step), "independent" (another scheme), "ode_form" (SciPy)
    status: str
    errors: dict[str, float]
    wall: float
    note: str = ""


@dataclass
class Reference:
    """The reference of one scene, its checks and the SciPy (ODE-form) reference."""

    scene: str
    main: ReferenceSolution
    ode: ReferenceSolution | None
    checks: list[ReferenceCheck]

    def uncertainty(self, measure: str) -> float:
        """The reference's error estimate for a measure: its difference to the halved step."""
        for c in self.checks:
            if c.kind == "twin":
                return c.errors.get(measure, math.nan)
        return math.nan

    def ode_gap(self, measure: str) -> float:
        """How far the converged ODE form lies from the reference (the SciPy floor)."""
        for c in self.checks:
            if c.kind == "ode_form" and c.status == "ok":
                return c.errors.get(measure, math.nan)
        return math.nan


def _tight(sc: Scenario) -> Scenario:
    """Our schemes with the reference's contact iteration tolerance (SciPy runs unchanged)."""
    if sc.solver.method not in OUR_METHODS:
        return sc
    sv = replace(sc.solver, tolerance=REF_TOLERANCE, max_iterations=REF_MAX_ITERATIONS)
    sv.validate()
    return replace(sc, solver=sv)


def _solution(label, method, value, sc, result, wall) -> ReferenceSolution:
    md = SortingModel(sc)
    return ReferenceSolution(
        label=label,
        method=method,
        value=value,
        trace=Trace(result),
        corners=np.array(md.body.corners, dtype=float),
        flexible=md.flexible,
        peak=result.peak_contact_force,
        sim_time=result.sim_time,
        steps=result.steps,
        wall=wall,
        t_sorted=dict(result.stages).get("sorted", math.nan),
    )


def reference(
    scene: str,
    *,
    quick: bool = False,
    max_wall: float = 600.0,
    progress: Progress = _quiet,
    base: Scenario | None = None,
) -> Reference:
    """The reference solution of ``scene`` with its halved-step, independent and ODE checks."""
    sc0 = base if base is not None else _load(scene)
    dt = REF_DT_QUICK if quick else REF_DT
    sc = _tight(configure(sc0, "trapezoidal", dt, max_wall))
    progress(f"{scene}: reference {describe('trapezoidal', dt)}")
    result, wall = timed(sc)
    if result.diagnosis is not None:
        raise RuntimeError(f"{scene}: the reference solve failed: {result.diagnosis}")
    label = f"trapezoidal dt = {dt:.6g} s, contact iteration tolerance {REF_TOLERANCE:g}"
    main = _solution(label, "trapezoidal", dt, sc, result, wall)
    del result
    checks: list[ReferenceCheck] = []
    specs = [
        ("twin", "trapezoidal", dt / 2.0, "trapezoidal at half the reference step"),
        ("independent", "generalized_alpha", dt, "generalized_alpha at the reference step"),
    ]
    ode_method, ode_rtol = ODE_REFERENCE.get(scene, ODE_REFERENCE_DEFAULT)
    specs.append(
        ("ode_form", ode_method, ode_rtol, f"{ode_method} rtol = {ode_rtol:g} (ODE form)")
    )
    ode = None
    for kind, method, value, text in specs:
        sck = _tight(configure(sc0, method, value, max_wall))
        progress(f"{scene}: reference check {describe(method, value)}")
        r, w = timed(sck)
        status = _status(r)
        errors = error_measures(r, main) if status == "ok" else {}
        checks.append(ReferenceCheck(text, kind, status, errors, w, r.diagnosis or ""))
        if kind == "ode_form" and status == "ok":
            ode = _solution(text, method, value, sck, r, w)
        del r
    if ode is not None:
        twin = ode_rtol / 10.0
        sck = configure(sc0, ode_method, twin, min(max_wall, ODE_TWIN_WALL))
        progress(f"{scene}: ODE-form check {describe(ode_method, twin)}")
        r, w = timed(sck)
        status = _status(r)
        errors = error_measures(r, ode) if status == "ok" else {}
        checks.append(
            ReferenceCheck(
                f"{ode_method} rtol = {twin:g} against the ODE-form reference",
                "ode_twin",
                status,
                errors,
                w,
                r.diagnosis or "",
            )
        )
    return Reference(scene, main, ode, checks)


# -- campaign -----------------------------------------------------------------------------------
@dataclass
class SceneResult:
    scene: str
    sim_time: float
    reference: Reference
    points: list[RunPoint]


@dataclass
class Campaign:
    scenes: list[SceneResult]
    methods: tuple[str, ...]
    quick: bool
    repeats: int
    max_wall: float
    command: str
    machine: dict[str, str]
    started: str
    duration: float = 0.0


def _load(scene: str) -> Scenario:
    return load_scene(scene).scenario


def machine_info() -> dict[str, str]:
    """The machine, the load at the start and the git revision the campaign ran on."""
    return {
        **machine.machine_info(),
        "load average at start": machine.load_average(),
        "git": machine.git_revision(),
    }


def run_campaign(
    scenes: Sequence[str] | None = None,
    methods: Sequence[str] | None = None,
    out_dir: Path | str | None = None,
    repeats: int = 3,
    quick: bool = False,
    *,
    max_wall: float = 30.0,
    command: str = "",
    progress: Progress = _quiet,
) -> Campaign:
    """Run the work-precision campaign; write the report into ``out_dir`` if given."""
    scenes = tuple(scenes or (QUICK_SCENES if quick else SCENES))
    methods = tuple(methods or (QUICK_METHODS if quick else METHODS))
    for m in methods:
        grid(m)  # rejects an unknown method before any solve
    t_start = time.perf_counter()
    campaign = Campaign(
        scenes=[],
        methods=methods,
        quick=quick,
        repeats=repeats,
        max_wall=max_wall,
        command=command,
        machine=machine_info(),
        started=time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    )
    for scene in scenes:
        sc0 = _load(scene)
        ref = reference(scene, quick=quick, progress=progress, base=sc0)
        points = []
        default = replace(sc0, record=RECORD, solver=replace(sc0.solver, max_wall_time=max_wall))
        timed(default)  # warm-up
        p = measure(scene, default, ref, repeats, is_default=True)
        progress(_line(p))
        points.append(p)
        for method in methods:
            values = grid(method, quick)
            warm = configure(sc0, method, values[0], min(max_wall, WARMUP_WALL))
            timed(warm)
            capped = None
            for value in values:
                if capped is not None:
                    points.append(
                        RunPoint(
                            scene,
                            method,
                            setting_name(method),
                            value,
                            "skipped",
                            note=f"skipped: {setting_name(method)} = {capped:g} already hit "
                            f"the {max_wall:g} s cap",
                        )
                    )
                    continue
                p = measure(scene, configure(sc0, method, value, max_wall), ref, repeats)
                progress(_line(p))
                points.append(p)
                if p.status == "capped":
                    capped = value
        campaign.scenes.append(SceneResult(scene, ref.main.sim_time, ref, points))
    campaign.duration = time.perf_counter() - t_start
    if out_dir is not None:
        write_report(campaign, out_dir)
    return campaign


def _line(p: RunPoint) -> str:
    err = " ".join(f"{k}={v:.2e}" for k, v in p.errors.items() if math.isfinite(v))
    tag = " (default)" if p.is_default else ""
    return (
        f"{p.scene}: {describe(p.method, p.value)}{tag}: {p.status}, wall {p.wall * 1e3:.1f} ms, "
        f"{p.steps} steps {err} {p.note}"
    ).rstrip()


# -- convergence and comparisons (numbers for the report) ---------------------------------------
def observed_order(points: Sequence[RunPoint], measure: str, floor: float) -> float:
    """Least-squares slope of log(error) over log(dt) (errors above 10x ``floor``)."""
    xs, ys = [], []
    for p in points:
        e = p.errors.get(measure, math.nan)
        if p.status == "ok" and math.isfinite(e) and e > 10.0 * max(floor, 0.0) and e > 0:
            xs.append(math.log(p.value))
            ys.append(math.log(e))
    if len(xs) < 3:
        return math.nan
    return float(np.polyfit(xs, ys, 1)[0])


def fastest_reaching(
    points: Sequence[RunPoint], measure: str, target: float, *, ode: bool = False
) -> RunPoint | None:
    """The quickest run that reaches ``target`` in ``measure`` and keeps it.

    A setting counts only if it and every tighter setting of the same method that finished
    have an error at most ``target`` (a lucky cancellation at one loose setting does not
    count). ``ode``: use the errors against the ODE-form reference.
    """

    def err(p: RunPoint) -> float:
        return (p.errors_ode if ode else p.errors).get(measure, math.inf)

    hits = []
    runs = [p for p in points if not p.is_default]
    for method in dict.fromkeys(p.method for p in runs):
        done = [p for p in runs if p.method == method and p.status == "ok"]
        for k, p in enumerate(done):
            if all(err(q) <= target for q in done[k:]):
                hits.append(p)
                break
    return min(hits, key=lambda p: p.wall) if hits else None


def non_monotone(points: Sequence[RunPoint], measure: str, factor: float = 2.0) -> bool:
    """Whether a tighter setting (later point) has an error ``factor`` times a looser one's."""
    errs = [p.errors.get(measure, math.nan) for p in points]
    errs = [e for e in errs if math.isfinite(e)]
    return any(b > factor * a for k, a in enumerate(errs) for b in errs[k + 1 :])


# -- report -------------------------------------------------------------------------------------
def _e(v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.2e}"


def _f(v: float, spec: str = ".2f") -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:{spec}}"


def _value(p: RunPoint) -> str:
    if p.setting == "dt":
        return f"dt {p.value * 1e3:.4g} ms"
    return f"rtol {p.value:.0e}"


def _measures(sr: SceneResult) -> tuple[str, ...]:
    main = sr.reference.main
    skip = set()
    if not main.flexible:
        skip.add("tip_deflection")
    if not main.runs_on_after_sort:
        skip.add("trajectory_to_sort")
    return tuple(m for m in MEASURES if m not in skip)


def plot_scene(sr: SceneResult, out_dir: Path) -> list[str]:
    """``<scene>_<measure>.png``: error against wall time, one curve per method, default star."""
    ref = sr.reference
    files = []
    for measure in _measures(sr):
        name = f"{sr.scene}_{measure}.png"
        plot_measure(
            sr.scene, measure, sr.points, ref.uncertainty(measure), ref.ode_gap(measure),
            out_dir / name,
        )  # fmt: skip
        files.append(name)
    return files


def plot_measure(
    scene: str,
    measure: str,
    points: Sequence[RunPoint],
    uncertainty: float,
    ode_gap: float,
    path: Path,
) -> Path:
    """One work-precision diagram: error in ``measure`` against wall time, one curve per
    method, the default as a star, the reference's own error and the ODE form's gap as lines;
    the legend beside the axes (never over the data)."""
    import matplotlib  # lazy: Matplotlib (0.7-1.3 s), only to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: Matplotlib (0.7-1.3 s), only to plot

    methods = list(dict.fromkeys(p.method for p in points if not p.is_default))
    fig, ax = plt.subplots(figsize=(9.0, 5.0))
    for method in methods:
        pts = [p for p in points if p.method == method and not p.is_default and p.status == "ok"]
        pts = [p for p in pts if p.errors.get(measure, math.nan) > 0]
        if not pts:
            continue
        (line,) = ax.loglog(
            [p.wall * 1e3 for p in pts],
            [p.errors[measure] for p in pts],
            marker=MARKERS.get(method, "o"),
            linestyle="--" if method.startswith("scipy:") else "-",
            label=method,
        )
        for p in {id(q): q for q in (pts[0], pts[-1])}.values():
            ax.annotate(
                _value(p).split(" ", 1)[1],
                (p.wall * 1e3, p.errors[measure]),
                textcoords="offset points",
                xytext=(4, 3),
                fontsize=6,
                color=line.get_color(),
            )
    for p in points:
        e = p.errors.get(measure, math.nan)
        if p.is_default and p.status == "ok" and e > 0:
            ax.loglog(
                [p.wall * 1e3],
                [e],
                marker="*",
                markersize=18,
                color="gold",
                markeredgecolor="black",
                linestyle="none",
                label=f"default ({describe(p.method, p.value)})",
                zorder=5,
            )
    if uncertainty > 0:
        ax.axhline(uncertainty, color="grey", linestyle=":", label="reference vs its halved step")
    if ode_gap > 0 and any(m.startswith("scipy:") for m in methods):
        ax.axhline(ode_gap, color="tab:red", linestyle="-.", lw=1, label="ODE form vs reference")
    title, unit = MEASURE_TEXT[measure]
    ax.set_title(f"{scene}: {title}")
    ax.set_xlabel("wall time per solve [ms] (median)")
    ax.set_ylabel(unit)
    ax.grid(True, which="both", alpha=0.3)
    ax.margins(x=0.08)  # room for the setting labels at the last points
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _nan(value):
    """A value of results.json back in Python: null -> NaN, also inside dicts."""
    if value is None:
        return math.nan
    if isinstance(value, dict):
        return {k: _nan(v) for k, v in value.items()}
    return value


def replot(out_dir: Path | str) -> list[Path]:
    """Redraw every ``<scene>_<measure>.png`` in ``out_dir`` from its ``results.json`` (the
    plots alone: no solve runs)."""
    out = Path(out_dir)
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    done = []
    for sc in data["scenes"]:
        points, ref, _ = scene_data(sc)
        for measure in MEASURES:
            path = out / f"{sc['scene']}_{measure}.png"
            if path.exists():
                unc, gap = ref.uncertainty(measure), ref.ode_gap(measure)
                done.append(plot_measure(sc["scene"], measure, points, unc, gap, path))
    return done


def save_reference(sr: SceneResult, out_dir: Path) -> str:
    """The reference sampled on the 1 ms grid (small; for inspection, not used as a cache)."""
    ref = sr.reference.main
    g = np.arange(0.0, ref.trace.t_end, GRID_STEP)
    x, y, phi = ref.trace.pose(g)
    arrays = {"t": g, "x": x, "y": y, "phi": phi}
    tip = ref.trace.tip_at(g)
    if tip is not None:
        arrays["tip_deflection"] = tip
    path = out_dir / "reference" / f"{sr.scene}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        **arrays,
        peak_contact_force=ref.peak,
        sim_time=ref.sim_time,
        label=np.array(ref.label),
    )
    return str(path.relative_to(out_dir))


def _reference_section(scenes: Sequence[dict]) -> list[str]:
    lines = ["## Reference solutions and their check", ""]
    for sc in scenes:
        points, ref, ms = scene_data(sc)
        main = sc["reference"]
        lines += [
            f"### {sc['scene']}",
            "",
            f"Reference: {main['label']}, {main['steps']} steps, "
            f"{main['sim_time']:.4f} s simulated, peak N = {main['peak_contact_force']:.6g} N, "
            f"wall {main['wall']:.1f} s.",
            "",
        ]
        rows = []
        for c in ref.checks:
            cells = (
                [_e(c.errors.get(m, math.nan)) for m in ms]
                if c.status == "ok"
                else ([c.status + ": " + c.note] + [""] * (len(ms) - 1))
            )
            rows.append([c.label, *cells, f"{c.wall:.1f}"])
        head = ["compared with the reference", *(MEASURE_TEXT[m][0] for m in ms), "wall [s]"]
        lines += table(head, rows)
        lines.append("")
        smallest = {m: _smallest(points, m) for m in ms}
        lines.append(
            "Smallest error reported below, per measure: "
            + ", ".join(f"{MEASURE_TEXT[m][0]} {_e(smallest[m])}" for m in ms)
            + "; reference vs halved step: "
            + ", ".join(f"{_e(ref.uncertainty(m))}" for m in ms)
            + "."
        )
        lines.append("")
    return lines


def _smallest(points: Sequence[RunPoint], measure: str) -> float:
    """The smallest error of the finished runs in ``measure`` (NaN if none)."""
    errs = [p.errors.get(measure, math.inf) for p in points if p.status == "ok"]
    small = min(errs, default=math.inf)
    return small if math.isfinite(small) else math.nan


def _scene_table(points: Sequence[RunPoint], ms: Sequence[str]) -> list[str]:
    head = ["method", "setting", "wall [ms]", "RTF", "steps"]
    head += [MEASURE_TEXT[m][0] for m in ms] + ["peak N vs ODE form", "note"]
    rows = []
    for p in points:
        name = f"**default** ({p.method})" if p.is_default else p.method
        if p.status == "skipped":
            rows.append([name, _value(p), "", "", "", *("" for _ in ms), "", p.note])
            continue
        errs = [_e(p.errors.get(m, math.nan)) if p.status == "ok" else "-" for m in ms]
        rtf = f"{p.rtf:.3g}"
        note = p.note
        if p.status == "capped":
            rtf += " (capped)"
            note = f"capped at {p.sim_time:.3f} s simulated: {note}"
        elif p.status == "failed":
            note = f"failed: {note}"
        if p.status == "ok" and not p.sorted:
            note = (note + "; " if note else "") + "not sorted"
        if len(p.walls) > 1:
            note = (note + "; " if note else "") + f"median of {len(p.walls)}"
        ode = _e(p.errors_ode.get("peak_force", math.nan)) if p.errors_ode else ""
        rows.append([name, _value(p), f"{p.wall * 1e3:.1f}", rtf, str(p.steps), *errs, ode, note])
    return table(head, rows)


def _unfinished_after(points: Sequence[RunPoint], hit: RunPoint) -> str:
    """ "; tighter settings ... did not finish" when some of them were not ok."""
    same = [p for p in points if p.method == hit.method and not p.is_default]
    later = same[same.index(hit) + 1 :]
    bad = [p for p in later if p.status != "ok"]
    if not bad:
        return ""
    return (
        f"; tighter {', '.join(_value(p) for p in bad)}: "
        f"{', '.join(sorted({p.status for p in bad}))}"
    )


def _run(p: RunPoint, default: RunPoint, points: Sequence[RunPoint]) -> str:
    """ "LSODA rtol 1e-04: 180.0 ms, 97x the default, error 2.1e-05" of a run."""
    return (
        f"{describe(p.method, p.value)}: {p.wall * 1e3:.1f} ms, {p.wall / default.wall:.3g}x "
        f"the default, error {_e(p.errors['peak_force'])}{_unfinished_after(points, p)}"
    )


def summary(points: Sequence[RunPoint], ref: Reference, ms: Sequence[str]) -> list[list[str]]:
    """The figures a scene's results come down to, as (figure, value) rows: the default, the
    fastest runs at its peak-force error, observed orders, the adaptive scheme over rtol, the
    reference's limits. How to read them: docs/design/verification.md."""
    rows: list[list[str]] = []
    default = next((p for p in points if p.is_default), None)
    scipy_pts = [p for p in points if p.method.startswith("scipy:")]
    if default is not None and default.status == "ok":
        e = default.errors["peak_force"]
        rows += [
            ["default", describe(default.method, default.value)],
            ["default: wall, RTF", f"{default.wall * 1e3:.1f} ms, {default.rtf:.3g}"],
            [
                "default: peak-force, trajectory, final-pose error",
                f"{_e(e)}, {_e(default.errors['trajectory'])} m, "
                f"{_e(default.errors['final_pose'])} m",
            ],
        ]
        hit = fastest_reaching(scipy_pts, "peak_force", e)
        if hit is not None:
            rows.append(["fastest SciPy run at that error", _run(hit, default, points)])
        elif scipy_pts:
            ok = [p for p in scipy_pts if p.status == "ok"]
            if ok:
                b = min(ok, key=lambda p: p.errors["peak_force"])
                closest = f"none; closest {_run(b, default, points)}"
                rows.append(["fastest SciPy run at that error", closest])
        hit = fastest_reaching(scipy_pts, "peak_force", e, ode=True)
        if hit is not None:
            what = "fastest SciPy run at that error of its own ODE form"
            rows.append([what, _run(hit, default, points)])
        ours = [p for p in points if p.method in OUR_METHODS and not p.is_default]
        hit = fastest_reaching(ours, "peak_force", e)
        if hit is not None and hit.wall < default.wall / 1.5:
            rows.append(["faster of ours at that error", _run(hit, default, points)])
        whole = default.errors.get("trajectory", math.nan)
        to_sort = default.errors.get("trajectory_to_sort", math.nan)
        if math.isfinite(to_sort):
            what = "default: trajectory error to the sort, whole run"
            rows.append([what, f"{_e(to_sort)} m, {_e(whole)} m"])
    elif default is not None:
        rows.append(["default", f"did not finish: {default.status}, {default.note}"])
    for method in ("trapezoidal", "generalized_alpha"):
        pts = [p for p in points if p.method == method]
        order_ms = [m for m in ms if m != "final_pose"]
        orders = {m: observed_order(pts, m, ref.uncertainty(m)) for m in order_ms}
        if any(math.isfinite(v) for v in orders.values()):
            rows.append(
                [
                    f"{method}: observed order in dt",
                    ", ".join(f"{_f(orders[m])} ({MEASURE_TEXT[m][0]})" for m in order_ms),
                ]
            )
    ad = [p for p in points if p.method == "adaptive" and p.status == "ok" and not p.is_default]
    ad = [p for p in ad if p.errors]
    if len(ad) >= 2:
        lo, hi = ad[0], ad[-1]
        monotone = not any(non_monotone(ad, m) for m in ("peak_force", "trajectory"))
        rows += [
            [
                f"adaptive rtol {lo.value:.0e} to {hi.value:.0e}: peak-force error",
                f"{_e(lo.errors['peak_force'])} to {_e(hi.errors['peak_force'])}",
            ],
            [
                f"adaptive rtol {lo.value:.0e} to {hi.value:.0e}: trajectory error",
                f"{_e(lo.errors['trajectory'])} to {_e(hi.errors['trajectory'])} m",
            ],
            [
                f"adaptive rtol {lo.value:.0e} to {hi.value:.0e}: wall",
                f"{lo.wall * 1e3:.1f} to {hi.wall * 1e3:.1f} ms",
            ],
            ["adaptive: errors monotone in rtol (within 2x)", "yes" if monotone else "no"],
        ]
    gap = ref.ode_gap("peak_force")
    if math.isfinite(gap):
        rows.append(
            [
                "ODE form vs reference: peak force, trajectory",
                f"{_e(gap)}, {_e(ref.ode_gap('trajectory'))} m "
                f"(reference vs halved step: {_e(ref.uncertainty('peak_force'))}, "
                f"{_e(ref.uncertainty('trajectory'))} m)",
            ]
        )
    unresolved = []
    for m in ms:
        unc = ref.uncertainty(m)
        small = _smallest(points, m)
        if math.isfinite(unc) and math.isfinite(small) and unc > 0.1 * small:
            unresolved.append(f"{MEASURE_TEXT[m][0]} (reference {_e(unc)}, smallest {_e(small)})")
    if unresolved:
        rows.append(["errors not resolved by the reference", "; ".join(unresolved)])
    for status in ("capped", "failed"):
        methods = sorted({p.method for p in scipy_pts if p.status == status})
        if methods:
            rows.append([f"SciPy methods {status}", ", ".join(methods)])
    return rows


def scene_data(sc: Mapping) -> tuple[list[RunPoint], Reference, tuple[str, ...]]:
    """One scene of results.json as run points, the reference's checks and the measures that
    apply to it (those with a finite error somewhere)."""
    names = set(RunPoint.__dataclass_fields__)
    points = [RunPoint(**{k: _nan(v) for k, v in p.items() if k in names}) for p in sc["points"]]
    checks = [ReferenceCheck(**_nan(c)) for c in sc["reference"]["checks"]]
    ms = tuple(
        m for m in MEASURES if any(math.isfinite(p.errors.get(m, math.nan)) for p in points)
    )
    return points, Reference(sc["scene"], None, None, checks), ms


def _settings(data: Mapping) -> list[str]:
    """The campaign's settings as a table, from the data."""

    def values(method: str) -> list[float]:
        return sorted(
            {
                p["value"]
                for sc in data["scenes"]
                for p in sc["points"]
                if p["method"] == method and not p["is_default"]
            },
            reverse=True,
        )

    scipy = {v for m in data["methods"] if m.startswith("scipy:") for v in values(m)}
    scipy = sorted(scipy, reverse=True)
    rows = [
        ["scenes", ", ".join(sc["scene"] for sc in data["scenes"])],
        ["methods", ", ".join(data["methods"])],
        ["adaptive rtol", ", ".join(f"{v:.0e}" for v in values("adaptive"))],
        ["fixed-step dt [ms]", ", ".join(f"{v * 1e3:.4g}" for v in values("trapezoidal"))],
        ["SciPy rtol", ", ".join(f"{v:.0e}" for v in scipy)],
        ["timed runs per setting (median)", str(data["repeats"])],
        ["wall-time cap per solve [s]", f"{data['max_wall_s']:g}"],
        ["reduced grid (--quick)", "yes" if data["quick"] else "no"],
    ]
    return table(["setting", "value"], rows)


def render_readme(data: Mapping) -> str:
    """README.md of a campaign from its results.json alone."""
    scenes = data["scenes"]
    lines = [
        "# Accuracy: work-precision diagrams of the time integrators",
        "",
        "Generated by `fence-sorter accuracy` (`fence_sorter/verification/accuracy.py`) from "
        "`results.json`; do not edit by hand. What is measured and how to read it: "
        "[docs/design/verification.md](../../design/verification.md#accuracy).",
        "",
        "Command:",
        "",
        "```",
        data["command"] or "fence-sorter accuracy",
        "```",
        "",
        f"Run {data['started']}, {data['duration_s'] / 60:.1f} min.",
        "",
    ]
    lines += table(["machine", ""], data["machine"].items())
    lines += ["", "## Settings", ""] + _settings(data) + [""]
    lines += _reference_section(scenes)
    lines += ["## Results", ""]
    for sc in scenes:
        points, ref, ms = scene_data(sc)
        lines += [f"### {sc['scene']}", ""]
        lines += [f"![{sc['scene']}_{m}.png]({sc['scene']}_{m}.png)" for m in ms]
        lines += ["", f"Reference sampled on the 1 ms grid: `reference/{sc['scene']}.npz`.", ""]
        lines += _scene_table(points, ms)
        lines += ["", "Summary:", ""]
        lines += table(["figure", "value"], summary(points, ref, ms))
        lines += [""]
    return "\n".join(lines)


def results_dict(campaign: Campaign) -> dict:
    """Everything the report shows, as plain JSON data (``results.json``)."""
    scenes = []
    for sr in campaign.scenes:
        ref = sr.reference
        scenes.append(
            {
                "scene": sr.scene,
                "reference": {
                    "label": ref.main.label,
                    "method": ref.main.method,
                    "value": ref.main.value,
                    "peak_contact_force": ref.main.peak,
                    "sim_time": ref.main.sim_time,
                    "steps": ref.main.steps,
                    "wall": ref.main.wall,
                    "checks": [asdict(c) for c in ref.checks],
                },
                "points": [dict(asdict(p), rtf=p.rtf) for p in sr.points],
            }
        )
    return json_safe(
        {
            "command": campaign.command,
            "started": campaign.started,
            "duration_s": campaign.duration,
            "machine": campaign.machine,
            "quick": campaign.quick,
            "repeats": campaign.repeats,
            "max_wall_s": campaign.max_wall,
            "methods": list(campaign.methods),
            "scenes": scenes,
        }
    )


def write_report(campaign: Campaign, out_dir: Path | str) -> Path:
    """results.json, the PNGs, the sampled references and README.md (rendered from
    results.json) into ``out_dir``; returns the README's path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    data = results_dict(campaign)
    (out_dir / "results.json").write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    for sr in campaign.scenes:
        plot_scene(sr, out_dir)
        save_reference(sr, out_dir)
    return rerender(out_dir)


def rerender(out_dir: Path | str) -> Path:
    """README.md of ``out_dir`` from its results.json (no solve runs)."""
    out_dir = Path(out_dir)
    data = json.loads((out_dir / "results.json").read_text(encoding="utf-8"))
    path = out_dir / "README.md"
    path.write_text(render_readme(data) + "\n", encoding="utf-8")
    return path


__all__ = [
    "Campaign",
    "METHODS",
    "MEASURES",
    "Reference",
    "ReferenceSolution",
    "RunPoint",
    "SCENES",
    "Trace",
    "configure",
    "error_measures",
    "grid",
    "reference",
    "render_readme",
    "rerender",
    "run_campaign",
    "summary",
    "write_report",
]
