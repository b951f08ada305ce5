"""The speed bench's settings and one timed run (:func:`timed_run`, the same for our runs and
the SciPy baselines), the two references of a scene and the default configuration's result
(see :mod:`benchmarks.bench`)."""

from __future__ import annotations

import dataclasses as dc
import gc
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fence_sorter.physics.params import CYRK_METHODS

SCENES = ("impact_flexible", "slide_flexible", "positioned_stiff", "arbitrary_stiff")
QUICK_SCENES = ("positioned_stiff",)
TARGET_RTF_SCENES = ("impact_flexible", "slide_flexible")
EVENT_SCENES = ("positioned_stiff", "arbitrary_stiff")

TARGET_ERROR = 1e-3  # relative peak-force error of the default configuration
TARGET_RTF = 75.0  # real-time factor of the default configuration (flexible scenes)
TARGET_SPEEDUP = 20.0  # default vs the fastest SciPy method at the same error
TARGET_PEER_SPEEDUP = 3.0  # default vs the fastest compiled peer (CyRK) at the same error
TARGET_EVENT_S = 5e-3  # one stiff-fence event (optimisation inner loop)

REFERENCE_DT = 1.5625e-5  # [s] our trapezoidal reference; checked at REFERENCE_DT / 2
# the reference's contact iteration converged to 1e-12 [m, m/s] (the default 1e-9 floors the
# trajectory at a few nm; the same choice as the accuracy campaign)
REFERENCE_TOLERANCE = 1e-12
REFERENCE_MAX_ITERATIONS = 30
SCIPY_REFERENCE = ("scipy:LSODA", 1e-10)  # checked at rtol / 10
QUICK_SCIPY_METHODS = ("scipy:LSODA", "scipy:BDF")
PEER_METHODS = CYRK_METHODS  # compiled peers: CyRK's C++ solvers on the same kernel.rhs
QUICK_PEER_METHODS = ("cyrk:LSODA",)
RTOL_LADDER = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
QUICK_RTOL_LADDER = (1e-3, 1e-5, 1e-7)
ATOL_FACTOR = 1e-2  # atol = rtol * ATOL_FACTOR for every SciPy run
BASELINE_REPEATS = 5
PARTS_ROUNDS = 3  # model-parts rounds per repeat (the runs are cheap, the noise is not)
RETIME_FACTOR = 5.0  # chosen SciPy rungs slower than this x the fastest one are not re-timed
SCIPY_CAP_S = 120.0  # solver.max_wall_time of every SciPy run
STIFF_FEM_MODULUS = 1.0e12  # [Pa] the largest FenceParams.validate allows
TRUNCATED_MODES = 4

JIT_SCENE = "impact_flexible"
JIT_T_END = 0.4  # [s] solver.t_end of the JIT / no-JIT comparison
JIT_REPEATS = 7
NOJIT_REPEATS = 3

Log = Callable[[str], None]


# -- small functions ------------------------------------------------------------------------------
def _median(xs: Sequence[float]) -> float:
    return statistics.median(xs) if xs else math.nan


def rel_error(value: float, ref: float) -> float:
    """|value - ref| / |ref| (nan when either is not finite or ref is 0)."""
    if not (math.isfinite(value) and math.isfinite(ref)) or ref == 0.0:
        return math.nan
    return abs(value - ref) / abs(ref)


def with_solver(sc, **changes):
    """The scenario with some ``solver`` fields replaced."""
    return dc.replace(sc, solver=dc.replace(sc.solver, **changes))


def _quiet(msg: str) -> None:
    del msg


@dataclass
class Outcome:
    """What one run answered (the physics, not the timing)."""

    success: bool
    sorted: bool
    peak_force: float
    exit_speed: float
    sim_time: float
    steps: int
    rejected: int
    diagnosis: str | None
    parts: tuple[str, ...] = ()

    @classmethod
    def of(cls, r) -> Outcome:
        return cls(
            success=r.success,
            sorted=r.sorted,
            peak_force=float(r.peak_contact_force),
            exit_speed=float(r.exit_speed_y),
            sim_time=float(r.sim_time),
            steps=int(r.steps),
            rejected=int(r.rejected_steps),
            diagnosis=r.diagnosis,
            parts=tuple(r.model_parts),
        )


def build_model(sc, force_border: bool = False):
    """``SortingModel(sc)``; ``force_border`` switches border contact on even when the load
    cannot reach the border (the model otherwise leaves it out)."""
    from fence_sorter.physics.simulate import SortingModel  # lazy: loads the kernel (Numba)

    md = SortingModel(sc)
    if force_border and not md.use_border:
        md.use_border = True
        md.P = md.P.copy()  # the scenario's packing is shared by its models
        md.P[0].use_border = 1.0
        parts = list(md.parts)
        at = parts.index("fem_fence" if md.flexible else "rigid_fence") + 1
        parts.insert(at, "border_contact")
        md.parts = tuple(parts)
    return md


def collect() -> None:
    """A garbage collection before a block of timed calls (none inside the block)."""
    gc.collect()


def timed_run(sc, force_border: bool = False) -> tuple[Outcome, float, float]:
    """One event, model build included: (outcome, wall [s], process CPU [s]).

    The garbage collector is off during the call (as in ``timeit``): no collection lands inside
    the timed call, and none runs just before it to leave the caches cold (call :func:`collect`
    before a block of calls instead). Every timed run of the benchmark, ours and SciPy's, goes
    through here."""
    from fence_sorter.physics.simulate import simulate  # lazy: loads the kernel (Numba), SciPy
    from fence_sorter.physics.stepper import collector_off

    with collector_off():
        c0 = time.process_time()
        t0 = time.perf_counter()
        r = simulate(sc, build_model(sc, force_border))
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
    return Outcome.of(r), wall, cpu


# -- references -----------------------------------------------------------------------------------
@dataclass
class Reference:
    """A converged peak force and the check of it at the next-tighter setting."""

    label: str
    check_label: str
    peak: float
    check_peak: float
    exit_speed: float
    wall: float
    check_wall: float
    success: bool
    diagnosis: str | None = None

    @property
    def check_change(self) -> float:
        """Relative change of the peak force from the reference to its check."""
        return rel_error(self.check_peak, self.peak)


def reference_solver(sc, dt: float):
    """Our reference run: trapezoidal at ``dt``, contact iteration converged tightly."""
    return with_solver(
        sc,
        method="trapezoidal",
        dt=dt,
        tolerance=REFERENCE_TOLERANCE,
        max_iterations=REFERENCE_MAX_ITERATIONS,
    )


def our_reference(sc) -> Reference:
    a, wa, _ = timed_run(reference_solver(sc, REFERENCE_DT))
    b, wb, _ = timed_run(reference_solver(sc, REFERENCE_DT / 2))
    return Reference(
        label=f"trapezoidal dt = {REFERENCE_DT:g} s, iteration tolerance {REFERENCE_TOLERANCE:g}",
        check_label=f"trapezoidal dt = {REFERENCE_DT / 2:g} s",
        peak=a.peak_force,
        check_peak=b.peak_force,
        exit_speed=a.exit_speed,
        wall=wa,
        check_wall=wb,
        success=a.success and b.success,
        diagnosis=a.diagnosis or b.diagnosis,
    )


def scipy_reference(sc, cap: float) -> Reference:
    method, rtol = SCIPY_REFERENCE
    runs = []
    for r in (rtol, rtol / 10):
        if runs and not runs[0][0].success:
            runs.append(runs[0])  # the reference failed: no check run
            break
        runs.append(
            timed_run(
                with_solver(sc, method=method, rtol=r, atol=r * ATOL_FACTOR, max_wall_time=cap)
            )
        )
    (a, wa, _), (b, wb, _) = runs
    if not a.success:
        wb = 0.0
    return Reference(
        label=f"{method} rtol = {rtol:g}",
        check_label=f"{method} rtol = {rtol / 10:g}",
        peak=a.peak_force if a.success else math.nan,
        check_peak=b.peak_force if b.success else math.nan,
        exit_speed=a.exit_speed,
        wall=wa,
        check_wall=wb,
        success=a.success and b.success,
        diagnosis=a.diagnosis or b.diagnosis,
    )


# -- the default configuration --------------------------------------------------------------------
@dataclass
class DefaultResult:
    scene: str
    method: str
    rtol: float
    atol: float
    dt_max: float
    record: tuple[str, ...]
    first_call: float  # [s] the warm-up call (on-disk Numba cache load included)
    walls: list[float]
    cpus: list[float]
    outcome: Outcome
    error: float  # relative peak-force error against our reference
    exit_speed_diff: float  # |exit speed - reference exit speed| [m/s]
    tracemalloc_peak: int = 0  # [bytes]

    @property
    def wall(self) -> float:
        return _median(self.walls)

    @property
    def cpu(self) -> float:
        return _median(self.cpus)

    @property
    def rtf(self) -> float:
        return self.outcome.sim_time / self.wall if self.wall > 0 else math.nan

    @property
    def rtf_cpu(self) -> float:
        """Real-time factor on process CPU time (what one uncontended core would give)."""
        return self.outcome.sim_time / self.cpu if self.cpu > 0 else math.nan
