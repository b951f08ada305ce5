"""The work-precision campaign's measurements (see :mod:`fence_sorter.verification.accuracy`):
the settings of each method, the error measures of one run against the reference, one timed
and measured run (:class:`RunPoint`), the reference and its checks, the campaign's results."""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from fence_sorter.physics.params import OUR_METHODS, SCIPY_METHODS
from fence_sorter.physics.simulate import Scenario, SimulationResult, SortingModel, simulate
from fence_sorter.scene import load_scene
from fence_sorter.verification import machine

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
