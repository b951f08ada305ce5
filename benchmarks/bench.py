"""Speed and memory benchmarks of the default configuration (``python -m benchmarks bench``).

Everything is measured side by side in one run of one process (plus a few fresh child
processes for what needs one: the kernel with the JIT disabled, a cold Numba cache, the resident
memory of one event). Per scene:

- **Reference** peak contact force: our ``trapezoidal`` scheme at ``dt = REFERENCE_DT``
  (1.5625e-5 s), checked against ``dt / 2``. The SciPy baselines integrate ``kernel.rhs`` (the
  ODE form, explicit Karnopp friction); their own converged answer (``scipy:LSODA`` at
  ``rtol = 1e-10``, checked against ``1e-11``) is the second reference, and the distance between
  the two is reported.
- **Default configuration**: the scene exactly as loaded (``solver.method = adaptive``). One
  warm-up call (its time, which includes loading the on-disk Numba cache, is reported as the
  first call), then the median of ``repeats`` calls of ``simulate(scenario)`` (model build
  included) timed with ``time.perf_counter``; steps, rejected steps, real-time factor
  (simulated time / wall time), relative peak-force error against the reference.
- **Timing method** (:func:`timed_run`, the same for our runs and every SciPy run): the garbage
  collector is disabled during each timed call and a collection runs before each block of
  repeats (:func:`collect`), not before each call, as ``timeit`` does. A ``gc.collect()`` right
  before a call walks every live object and leaves the CPU caches cold (positioned_stiff: median
  0.66 ms timed that way, 0.49 ms warm; LSODA at rtol 1e-3 on it 4.78 and 4.01 ms), while an
  optimisation inner loop runs events back to back, warm.
- **Compiled peers** (``cyrk:LSODA ... Tsit5``, ``physics.peers``): CyRK's C++ solvers on the
  same compiled right-hand side, no Python per right-hand side; the same ladder search, choice
  and interleaved timing as the SciPy baselines below, reported first (the honest ratio).
- **SciPy baselines** (``scipy:RK45 ... LSODA``): for each method, a ladder of ``rtol`` values
  (``atol = rtol * ATOL_FACTOR``), loosest first, each run capped by ``solver.max_wall_time``;
  the loosest rung whose peak-force error is at most the default's ("the same error"; if no
  method reaches it, the 1e-3 target, and the report says so) and stays so at the next tighter
  rung (the fastest candidates are confirmed, :func:`search_rungs`) is timed again (median of 5,
  interleaved with the default's timed runs) and the fastest such method is compared with the
  default. The error is measured two ways: against our reference, and against the SciPy
  reference (the accuracy of a solver on the model it integrates).
- **Memory**: ``tracemalloc`` peak of one default run (Python and NumPy allocations made by the
  run) and the maximum resident set size (``getrusage``) of a fresh process that runs one event.
- **Model parts**: the scene as built against variants that leave nothing out (every time series
  recorded, border contact forced on, for a stiff scene a flexible fence at the largest allowed
  Young's modulus with every mode), interleaved; the outcome of each against the built one.
- **Compiled kernel**: the same script in two fresh processes, with and without
  ``NUMBA_DISABLE_JIT=1``, on a shortened ``impact_flexible``; and the first call with a cold
  Numba cache (compilation).

Functions return plain dataclasses; :func:`render_markdown` turns a :class:`BenchReport` into
``docs/reports/benchmarks.md``.
"""

from __future__ import annotations

import dataclasses as dc
import gc
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
import types
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime

from benchmarks import REPO
from fence_sorter.jsonsafe import json_safe
from fence_sorter.physics.params import CYRK_METHODS, SCIPY_METHODS, FenceParams
from fence_sorter.physics.scenario import RECORDABLE
from fence_sorter.scene import load_scene
from fence_sorter.verification.machine import git_revision, load_average, machine_info
from fence_sorter.verification.report import table

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


# -- machine --------------------------------------------------------------------------------------
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


# -- SciPy baselines ------------------------------------------------------------------------------
@dataclass
class LadderRun:
    method: str
    rtol: float
    atol: float
    wall: float
    outcome: Outcome
    err_ref: float  # against our reference
    err_self: float  # against the SciPy reference
    capped: bool

    @property
    def ok(self) -> bool:
        return self.outcome.success and not self.capped


@dataclass
class Choice:
    """A method's loosest ladder rung reaching a threshold, timed (median of BASELINE_REPEATS)."""

    method: str
    run: LadderRun | None  # None: no rung reached the threshold
    walls: list[float] = field(default_factory=list)
    note: str = ""

    @property
    def wall(self) -> float:
        return _median(self.walls)


@dataclass
class Comparison:
    """The default against the fastest SciPy method reaching ``threshold`` in ``metric``."""

    metric: str  # "ref" (our reference) or "self" (the SciPy reference)
    threshold: float
    relaxed: bool  # True: nobody reached the default's error, threshold = the 1e-3 target
    choices: list[Choice]
    default_wall: float

    @property
    def best(self) -> Choice | None:
        timed = [c for c in self.choices if c.run is not None and c.walls]
        return min(timed, key=lambda c: c.wall) if timed else None

    @property
    def ratio(self) -> float:
        b = self.best
        return b.wall / self.default_wall if b is not None and self.default_wall > 0 else math.nan


@dataclass
class BaselineResult:
    scene: str
    runs: list[LadderRun]
    by_ref: Comparison
    by_self: Comparison
    cap: float

    def next_rung(self, run: LadderRun) -> LadderRun | None:
        """The same method's run at the next tighter rtol, if the ladder went on."""
        later = [r for r in self.runs if r.method == run.method and r.rtol < run.rtol]
        return max(later, key=lambda r: r.rtol) if later else None

    def fastest_any(self) -> LadderRun | None:
        """The fastest finished run of the whole ladder, whatever its error."""
        ok = [r for r in self.runs if r.ok]
        return min(ok, key=lambda r: r.wall) if ok else None


def ladder_done(run: LadderRun, error: float, gap: float) -> bool:
    """Whether a tighter rung can still change the choice for either metric.

    Done when the run reaches the default's ``error`` against the SciPy reference and, against
    our reference, either reaches it too or can no longer get closer: the run sits on the SciPy
    reference (within a tenth of the ``gap`` between the two references) and every threshold
    still unmet (the default's error, the 1e-3 target) lies below 0.9 of that gap.
    """
    if not run.ok:
        return False
    if not math.isfinite(gap):  # no SciPy reference: our reference alone decides
        return run.err_ref <= error
    if not run.err_self <= error:
        return False
    if run.err_ref <= error:
        return True
    if not run.err_self < 0.1 * gap:
        return False
    unmet = [error] + (
        [TARGET_ERROR] if TARGET_ERROR > error and run.err_ref > TARGET_ERROR else []
    )
    return all(t < 0.9 * gap for t in unmet)


def ladder_search(
    sc,
    methods: Sequence[str],
    ladder: Sequence[float],
    ref_peak: float,
    self_peak: float,
    error: float,
    cap: float,
    log: Log = _quiet,
) -> list[LadderRun]:
    """Run each method down the rtol ladder (loosest first) until :func:`ladder_done` (the
    default's ``error`` reached, or the SciPy answer converged onto the gap between the two
    references) or a run hits the wall-time cap (a tighter tolerance would take longer still),
    then confirm the fastest candidates (:func:`search_rungs`).
    """

    def run_rung(method: str, rtol: float) -> LadderRun:
        atol = rtol * ATOL_FACTOR
        o, wall, _ = timed_run(
            with_solver(sc, method=method, rtol=rtol, atol=atol, max_wall_time=cap)
        )
        capped = bool(o.diagnosis and "wall-time limit" in o.diagnosis)
        run = LadderRun(
            method=method,
            rtol=rtol,
            atol=atol,
            wall=wall,
            outcome=o,
            err_ref=rel_error(o.peak_force, ref_peak) if o.success else math.nan,
            err_self=rel_error(o.peak_force, self_peak) if o.success else math.nan,
            capped=capped,
        )
        state = "capped" if capped else ("ok" if o.success else "failed")
        log(
            f"  {method:13s} rtol {rtol:7.0e}  {wall:8.3f} s  {o.steps:7d} steps  "
            f"err {run.err_ref:.2e} (ref) {run.err_self:.2e} (scipy ref)  {state}"
        )
        return run

    return search_rungs(methods, ladder, run_rung, error, rel_error(self_peak, ref_peak))


def search_rungs(
    methods: Sequence[str],
    ladder: Sequence[float],
    run_rung: Callable[[str, float], LadderRun],
    error: float,
    gap: float,
) -> list[LadderRun]:
    """The ladder search proper, ``run_rung(method, rtol)`` running one solve.

    Descent: each method runs down the ladder to its first rung that is :func:`ladder_done`
    (or to a capped run). Confirmation: a rung may reach the error by a cancellation of errors
    and lose it at the next tighter tolerance (LSODA on positioned_stiff: rtol 1e-3 within
    1e-5 of the reference, rtol 1e-4 off by 8e-4), so each candidate (the loosest done rung of
    a method whose next tighter rung did not refute it) within RETIME_FACTOR of the fastest
    candidate's search run, fastest first, has its next rung run; a refuted method descends on
    to its next done rung. It ends when every such candidate is confirmed (its next rung also
    done, failed, or beyond the ladder). Slower candidates stay unconfirmed: they are not
    re-timed and cannot be the baseline the default is compared with. (Confirming only the
    fastest search run was not enough: single runs of a few ms are noisy, RK45 rtol 1e-2 came
    out 1 ms faster than LSODA rtol 1e-3 in one, and the re-timed medians then chose LSODA's
    unconfirmed rung.)
    """
    runs: list[LadderRun] = []

    def descend(method: str, first: int) -> None:
        for rtol in ladder[first:]:
            run = run_rung(method, rtol)
            runs.append(run)
            if run.capped or ladder_done(run, error, gap):
                return

    for method in methods:
        collect()
        descend(method, 0)
    while True:
        cands = [c for m in methods if (c := _candidate(runs, m, error, gap)) is not None]
        if not cands:
            return runs
        fastest = min(c.wall for c in cands)
        # every candidate that will be re-timed (within RETIME_FACTOR of the fastest) must be
        # confirmed: the re-timed medians, not these single search runs, pick the baseline
        open_ = [
            c
            for c in cands
            if c.wall <= RETIME_FACTOR * fastest
            and not any(r.method == c.method and r.rtol < c.rtol for r in runs)
            and list(ladder).index(c.rtol) + 1 < len(ladder)
        ]
        if not open_:
            return runs
        c = min(open_, key=lambda r: r.wall)
        collect()
        descend(c.method, list(ladder).index(c.rtol) + 1)


def _candidate(runs: Sequence[LadderRun], method: str, error: float, gap: float):
    """The method's loosest :func:`ladder_done` rung that its next tighter rung, if it ran,
    does not refute (a refuting rung finished and is not done)."""
    mine = [r for r in runs if r.method == method]  # ladder order: loosest first
    for i, r in enumerate(mine):
        if ladder_done(r, error, gap):
            nxt = mine[i + 1] if i + 1 < len(mine) else None
            if nxt is None or not nxt.ok or ladder_done(nxt, error, gap):
                return r
    return None


def _loosest(runs: Sequence[LadderRun], method: str, metric: str, thr: float):
    """The method's loosest rung reaching ``thr`` whose next tighter rung, if it ran, reaches
    it too (a rung that met it by a cancellation of errors and lost it at the next tolerance
    is skipped)."""

    def err(r: LadderRun) -> float:
        return r.err_ref if metric == "ref" else r.err_self

    mine = [r for r in runs if r.method == method]  # ladder order: loosest first
    for i, r in enumerate(mine):
        if r.ok and math.isfinite(err(r)) and err(r) <= thr:
            nxt = mine[i + 1] if i + 1 < len(mine) else None
            if nxt is None or not nxt.ok or err(nxt) <= thr:
                return r
    return None


def choose(runs, methods, metric: str, default_error: float) -> tuple[float, bool, list[Choice]]:
    """Threshold and each method's loosest rung: the default's error, else the 1e-3 target."""
    thresholds = [(default_error, False)]
    if TARGET_ERROR > default_error:
        thresholds.append((TARGET_ERROR, True))
    for thr, relaxed in thresholds:
        picks = [Choice(m, _loosest(runs, m, metric, thr)) for m in methods]
        if any(c.run is not None for c in picks):
            return thr, relaxed, picks
    thr, relaxed = thresholds[-1]
    return thr, relaxed, [Choice(m, None) for m in methods]


# -- model parts ----------------------------------------------------------------------------------
@dataclass
class PartsVariant:
    label: str
    role: str  # "built", "leaner", "fuller", "full", "truncated"
    same_physics: bool
    parts: tuple[str, ...]
    walls: list[float]
    outcome: Outcome

    @property
    def wall(self) -> float:
        return _median(self.walls)


@dataclass
class PartsResult:
    scene: str
    variants: list[PartsVariant]
    note: str = ""

    def get(self, role: str) -> PartsVariant | None:
        return next((v for v in self.variants if v.role == role), None)


def parts_variants(sc) -> list[tuple[str, str, bool, object, bool]]:
    """(label, role, same physics, scenario, force border) of the model-parts comparison."""
    md = build_model(sc)
    out = [("as built (the scene)", "built", True, sc, False)]
    if sc.record:
        out.append(("no time series recorded", "leaner", True, dc.replace(sc, record=()), False))
    full_sc, full_border, fuller = sc, False, []
    if set(sc.record) != set(RECORDABLE):
        rec = dc.replace(sc, record=RECORDABLE)
        out.append(("+ every time series recorded", "fuller", True, rec, False))
        full_sc = dc.replace(full_sc, record=RECORDABLE)
        fuller.append("records")
    if not md.use_border:
        out.append(("+ border contact forced on", "fuller", True, sc, True))
        full_border = True
        fuller.append("border")
    if sc.fence is None:
        fp = FenceParams(length=sc.fence_length, youngs_modulus=STIFF_FEM_MODULUS)
        fem = dc.replace(sc, fence=fp, fence_modes=None)
        label = f"+ FEM fence E = {STIFF_FEM_MODULUS:g} Pa, all modes"
        out.append((label, "fuller", False, fem, False))
        full_sc = dc.replace(full_sc, fence=fp, fence_modes=None)
        fuller.append("fem")
    elif sc.fence_modes is not None:
        out.append(("+ every fence mode", "fuller", True, dc.replace(sc, fence_modes=None), False))
        full_sc = dc.replace(full_sc, fence_modes=None)
        fuller.append("modes")
    if len(fuller) > 1:
        same = sc.fence is not None
        out.append(("full model (nothing left out)", "full", same, full_sc, full_border))
    elif fuller:
        label, _, same, s, b = out[-1]
        out[-1] = (label + " = full model", "full", same, s, b)
    if sc.fence is not None:
        n = TRUNCATED_MODES
        if md.n_modes > n:
            label = f"fence.modes = {n} (truncated; not the scene's choice)"
            out.append((label, "truncated", False, dc.replace(sc, fence_modes=n), False))
    return out


def model_parts(sc, repeats: int, log: Log = _quiet) -> PartsResult:
    """Time the variants round-robin (``repeats`` rounds) and keep each one's outcome."""
    specs = parts_variants(sc)
    walls: list[list[float]] = [[] for _ in specs]
    outcomes: list[Outcome | None] = [None] * len(specs)
    for _, _, _, s, b in specs:  # warm-up (a new model shape can need a cache load)
        timed_run(s, b)
    collect()
    n = len(specs)
    for k in range(repeats):
        for i in [(k + j) % n for j in range(n)]:  # rotated: no variant always runs first
            _, _, _, s, b = specs[i]
            o, w, _ = timed_run(s, b)
            walls[i].append(w)
            outcomes[i] = o
    variants = [
        PartsVariant(label, role, same, outcomes[i].parts, walls[i], outcomes[i])
        for i, (label, role, same, _, _) in enumerate(specs)
    ]
    for v in variants:
        log(f"  {v.label:52s} {v.wall * 1e3:9.2f} ms  peak {v.outcome.peak_force:.6g} N")
    return PartsResult(scene="", variants=variants)


# -- child processes: JIT on / off, cold cache, resident memory -----------------------------------
_CHILD = r"""
import json, resource, sys, time
def hwm_kib():
    # VmHWM: this process's peak resident set (ru_maxrss can carry the parent's across exec)
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
from fence_sorter.physics.params import FenceParams
from fence_sorter.physics.scenario import RECORDABLE
from fence_sorter.scene import load_scene
from fence_sorter.physics.simulate import simulate
import numba
t_import = time.perf_counter() - t0
args = json.loads(sys.argv[1])
sc = load_scene(args["scene"], args["overrides"]).scenario
rss0 = hwm_kib()
walls, peaks, steps = [], [], []
for _ in range(args["runs"]):
    t = time.perf_counter()
    r = simulate(sc)
    walls.append(time.perf_counter() - t)
    peaks.append(r.peak_contact_force)
    steps.append(r.steps)
print(json.dumps({
    "import_s": t_import, "walls": walls, "peaks": peaks, "steps": steps,
    "sim_time": r.sim_time, "success": r.success,
    "rss_after_import_kib": rss0,
    "rss_kib": hwm_kib(),
    "jit_disabled": bool(numba.config.DISABLE_JIT),
}))
"""


def run_child(scene: str, overrides: Sequence[str], runs: int, env_changes: dict) -> dict:
    """Run ``simulate`` ``runs`` times on a scene in a fresh Python process; its JSON report."""
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop("NUMBA_CACHE_DIR", None)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env.update(env_changes)
    arg = json.dumps({"scene": scene, "overrides": list(overrides), "runs": runs})
    p = subprocess.run(
        [sys.executable, "-c", _CHILD, arg],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
        timeout=1800,
        check=False,
    )
    if p.returncode != 0:
        tail = (p.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"benchmark child process failed ({p.returncode}): {tail}")
    return json.loads(p.stdout.strip().splitlines()[-1])


@dataclass
class JitResult:
    scene: str
    t_end: float
    sim_time: float
    steps: int
    jit_walls: list[float]  # warm calls, JIT on (the warm-up call excluded)
    nojit_walls: list[float]  # NUMBA_DISABLE_JIT=1 (the first call excluded)
    jit_peak: float
    nojit_peak: float
    jit_child_confirmed: bool  # the child reported the JIT disabled
    warm_cache_first_call: float  # [s] first call with the on-disk cache
    cold_first_call: float = math.nan  # [s] first call with an empty cache (compilation)
    cold_second_call: float = math.nan
    cold_scene: str = ""

    @property
    def jit_wall(self) -> float:
        return _median(self.jit_walls)

    @property
    def nojit_wall(self) -> float:
        return _median(self.nojit_walls)

    @property
    def ratio(self) -> float:
        return self.nojit_wall / self.jit_wall if self.jit_wall > 0 else math.nan


def jit_comparison(jit_repeats: int, nojit_repeats: int, cold: bool, log: Log = _quiet):
    overrides = [f"solver.t_end={JIT_T_END}"]
    log(f"JIT on: {JIT_SCENE} to t = {JIT_T_END} s, 1 + {jit_repeats} calls in a fresh process")
    on = run_child(JIT_SCENE, overrides, 1 + jit_repeats, {})
    log(f"JIT off (NUMBA_DISABLE_JIT=1): 1 + {nojit_repeats} calls in a fresh process")
    off = run_child(JIT_SCENE, overrides, 1 + nojit_repeats, {"NUMBA_DISABLE_JIT": "1"})
    res = JitResult(
        scene=JIT_SCENE,
        t_end=JIT_T_END,
        sim_time=on["sim_time"],
        steps=on["steps"][-1],
        jit_walls=on["walls"][1:],
        nojit_walls=off["walls"][1:],
        jit_peak=on["peaks"][-1],
        nojit_peak=off["peaks"][-1],
        jit_child_confirmed=off["jit_disabled"] and not on["jit_disabled"],
        warm_cache_first_call=on["walls"][0],
    )
    if cold:
        log(f"cold Numba cache: first call of {JIT_SCENE} (compiles the kernel)")
        with tempfile.TemporaryDirectory(prefix="fence_sorter_numba_") as d:
            c = run_child(JIT_SCENE, [], 2, {"NUMBA_CACHE_DIR": d})
        res.cold_first_call, res.cold_second_call = c["walls"][0], c["walls"][1]
        res.cold_scene = JIT_SCENE
    return res


def peak_rss_kib() -> int:
    """This process's peak resident set size [KiB] (VmHWM; getrusage's ru_maxrss without
    /proc)."""
    try:
        with open("/proc/self/status", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


@dataclass
class MemoryResult:
    scene: str
    tracemalloc_peak: int  # [bytes] one default run, in this process
    rss_after_import_kib: int  # fresh process: imports and scene loaded
    rss_after_run_kib: int  # fresh process: after one event


# -- the whole bench ------------------------------------------------------------------------------
@dataclass
class BeltProbe:
    """Both references again with ``conveyor.mu_belt = 0`` (no belt friction)."""

    ours_peak: float
    scipy_peak: float

    @property
    def gap(self) -> float:
        return rel_error(self.scipy_peak, self.ours_peak)


def belt_probe(name: str, cap: float) -> BeltProbe:
    sc = load_scene(name, ["conveyor.mu_belt=0"]).scenario
    method, rtol = SCIPY_REFERENCE
    a, _, _ = timed_run(reference_solver(sc, REFERENCE_DT))
    b, _, _ = timed_run(
        with_solver(sc, method=method, rtol=rtol, atol=rtol * ATOL_FACTOR, max_wall_time=cap)
    )
    return BeltProbe(a.peak_force, b.peak_force if b.success else math.nan)


@dataclass
class SceneBench:
    scene: str
    ours: Reference
    scipy_ref: Reference
    default: DefaultResult
    baselines: BaselineResult
    parts: PartsResult
    memory: MemoryResult
    belt: BeltProbe | None = None  # when the two references disagree beyond their convergence
    peers: BaselineResult | None = None  # the compiled peers' ladder (None: not run)


@dataclass
class TargetCheck:
    target: str
    scene: str
    measured: str
    limit: str
    verdict: str  # PASS, FAIL, N/A
    note: str = ""


@dataclass
class BenchReport:
    command: str
    started: str
    finished: str
    commit: str
    machine: dict[str, str]
    load_before: str
    load_after: str
    options: dict
    scenes: list[SceneBench]
    jit: JitResult
    process_max_rss_kib: int
    total_wall: float
    targets: list[TargetCheck] = field(default_factory=list)


def _comparisons(runs, methods, error) -> tuple[list[Comparison], dict]:
    """Per metric, the :class:`Comparison` of a family's methods and their chosen rungs; and
    the chosen rungs by (method, rtol) (one rung can serve both metrics: timed once, shared)."""
    comps = []
    for metric in ("ref", "self"):
        thr, relaxed, picks = choose(runs, methods, metric, error)
        comps.append(Comparison(metric, thr, relaxed, picks, math.nan))
    by_run: dict[tuple[str, float], list[Choice]] = {}
    for comp in comps:
        for c in comp.choices:
            if c.run is not None:
                by_run.setdefault((c.method, c.run.rtol), []).append(c)
    # a rung whose search run took over RETIME_FACTOR x the fastest candidate's cannot be the
    # fastest: its single search run stands, it is not timed again
    fastest = min((cs[0].run.wall for cs in by_run.values()), default=math.nan)
    retime = {}
    for key, cs in by_run.items():
        if cs[0].run.wall <= RETIME_FACTOR * fastest:
            retime[key] = cs
        else:
            for c in cs:
                c.walls = [cs[0].run.wall]
                c.note = f"single search run, over {RETIME_FACTOR:g}x the fastest: not re-timed"
    return comps, retime


def bench_scene(
    name: str,
    repeats: int,
    methods: Sequence[str],
    ladder: Sequence[float],
    cap: float,
    log: Log = _quiet,
    peer_methods: Sequence[str] = (),
) -> SceneBench:
    sc = load_scene(name).scenario
    sv = sc.solver

    log(f"[{name}] warm-up call of the default configuration ({sv.method})")
    collect()
    first, first_wall, _ = timed_run(sc)

    log(f"[{name}] references: trapezoidal dt = {REFERENCE_DT:g} s and dt / 2")
    ours = our_reference(sc)
    log(
        f"  peak {ours.peak:.9g} N, check {ours.check_peak:.9g} N "
        f"(change {ours.check_change:.1e}), {ours.wall + ours.check_wall:.1f} s"
    )
    method, rtol = SCIPY_REFERENCE
    log(f"[{name}] SciPy reference: {method} rtol = {rtol:g} and rtol / 10")
    sref = scipy_reference(sc, cap)
    log(
        f"  peak {sref.peak:.9g} N, check {sref.check_peak:.9g} N "
        f"(change {sref.check_change:.1e}); {rel_error(sref.peak, ours.peak):.1e} from ours"
    )
    error = rel_error(first.peak_force, ours.peak)
    gap = rel_error(sref.peak, ours.peak)
    belt = None
    if gap > 10 * max(ours.check_change, sref.check_change, 1e-12):
        log(f"[{name}] the references differ by {gap:.1e}: both again with conveyor.mu_belt = 0")
        belt = belt_probe(name, cap)
        log(f"  without belt friction they differ by {belt.gap:.1e}")

    # the compiled peers first (the honest comparison), then SciPy; the same ladder search
    peer_runs, peer_comps, retime = [], [], {}
    if peer_methods:
        log(f"[{name}] compiled-peer ladder: {', '.join(peer_methods)}")
        timed_run(with_solver(sc, method=peer_methods[0], max_wall_time=cap))  # compiles
        peer_runs = ladder_search(sc, peer_methods, ladder, ours.peak, sref.peak, error, cap, log)
        peer_comps, retime = _comparisons(peer_runs, peer_methods, error)
    log(f"[{name}] SciPy ladder: {', '.join(methods)}; rtol {ladder[0]:g} .. {ladder[-1]:g}")
    runs = ladder_search(
        sc,
        methods,
        ladder,
        ours.peak,
        sref.peak,
        error,
        cap,
        log,
    )
    comps, scipy_retime = _comparisons(runs, methods, error)
    retime.update(scipy_retime)

    log(
        f"[{name}] timing: {repeats} calls of the default interleaved with "
        f"{BASELINE_REPEATS} of each chosen rung within {RETIME_FACTOR:g}x of its family's "
        f"fastest ({len(retime)})"
    )
    walls, cpus = [], []
    collect()
    for i in range(max(repeats, BASELINE_REPEATS if retime else 0)):
        if i < repeats:
            o, w, c = timed_run(sc)
            walls.append(w)
            cpus.append(c)
        if i < BASELINE_REPEATS:
            for (m, r), cs in retime.items():
                run_sc = with_solver(sc, method=m, rtol=r, atol=r * ATOL_FACTOR, max_wall_time=cap)
                o2, w2, _ = timed_run(run_sc)
                for c in cs:
                    c.walls.append(w2)
                    if not o2.success:
                        c.note = f"a timing run failed: {o2.diagnosis}"
    default = DefaultResult(
        scene=name,
        method=sv.method,
        rtol=sv.rtol,
        atol=sv.atol,
        dt_max=sv.dt_max,
        record=tuple(sc.record),
        first_call=first_wall,
        walls=walls,
        cpus=cpus,
        outcome=first,
        error=error,
        exit_speed_diff=abs(first.exit_speed - ours.exit_speed),
    )
    for comp in comps + peer_comps:
        comp.default_wall = default.wall
    log(
        f"  default: {default.wall * 1e3:.2f} ms median, {default.rtf:.1f}x real time, "
        f"error {error:.2e}"
    )

    gc.collect()
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        timed_run(sc)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    default.tracemalloc_peak = peak
    log(f"[{name}] memory: tracemalloc peak {peak / 1024:.0f} KiB; fresh-process RSS")
    child = run_child(name, [], 1, {})
    memory = MemoryResult(
        scene=name,
        tracemalloc_peak=peak,
        rss_after_import_kib=int(child["rss_after_import_kib"]),
        rss_after_run_kib=int(child["rss_kib"]),
    )

    log(f"[{name}] model parts: {PARTS_ROUNDS * repeats} interleaved rounds")
    parts = model_parts(sc, PARTS_ROUNDS * repeats, log)
    parts.scene = name
    return SceneBench(
        scene=name,
        ours=ours,
        scipy_ref=sref,
        default=default,
        baselines=BaselineResult(name, runs, comps[0], comps[1], cap),
        parts=parts,
        memory=memory,
        belt=belt,
        peers=BaselineResult(name, peer_runs, *peer_comps, cap) if peer_comps else None,
    )


def _sustained_note(b: BaselineResult, comp: Comparison) -> str:
    best = comp.best
    nxt = b.next_rung(best.run) if best is not None else None
    if nxt is None or not nxt.ok:
        return ""
    e2 = nxt.err_self if comp.metric == "self" else nxt.err_ref
    if math.isfinite(e2) and e2 > comp.threshold:
        return (
            f"; not sustained: at rtol {nxt.rtol:g} the error is {e2:.1e} (the chosen rung "
            "reached the threshold by a cancellation of errors)"
        )
    return ""


def _speedup_checks(sb: SceneBench, b: BaselineResult, family: str, limit: float):
    """The speed-up targets of the default against a family's fastest method at the same
    error, against the SciPy reference and against ours."""
    out = []
    d = sb.default
    for comp in (b.by_self, b.by_ref):
        which = "SciPy's own converged answer" if comp.metric == "self" else "our reference"
        target = f"speed-up vs fastest {family} at the same error ({comp.metric})"
        b_ = comp.best
        digits = 1 if math.isfinite(comp.ratio) and comp.ratio < 10 else 0
        if comp.metric == "self" and not math.isfinite(sb.scipy_ref.peak):
            out.append(
                TargetCheck(
                    target,
                    sb.scene,
                    "no SciPy reference",
                    f">= {limit:g}x",
                    "N/A",
                    f"the SciPy reference run ({sb.scipy_ref.label}) did not finish: "
                    f"{sb.scipy_ref.diagnosis}",
                )
            )
            continue
        thr = f"error <= {comp.threshold:.1e} vs {which}"
        if comp.relaxed:
            thr += " (relaxed to the 1e-3 target: no method reached the default's error)"
        if b_ is None:
            lb = b.fastest_any()
            note = f"no {family} method on the ladder reached it"
            if lb is not None:
                note += (
                    f"; the fastest finished {family} run at any error ({lb.method} rtol "
                    f"{lb.rtol:g}, error {lb.err_ref:.1e} vs our reference) took "
                    f"{lb.wall / d.wall:.0f}x the default's time"
                )
            out.append(
                TargetCheck(
                    target, sb.scene, "none reached", f">= {limit:g}x", "N/A", f"{thr}: {note}"
                )
            )
            continue
        out.append(
            TargetCheck(
                target,
                sb.scene,
                f"{comp.ratio:.{digits}f}x ({b_.method} rtol {b_.run.rtol:g})",
                f">= {limit:g}x",
                "PASS" if comp.ratio >= limit else "FAIL",
                thr + _sustained_note(b, comp),
            )
        )
    return out


def evaluate_targets(scenes: Sequence[SceneBench]) -> list[TargetCheck]:
    out = []
    for sb in scenes:
        d = sb.default
        if sb.scene in TARGET_RTF_SCENES:
            out.append(
                TargetCheck(
                    "peak-force error of the default",
                    sb.scene,
                    f"{d.error:.1e}",
                    f"<= {TARGET_ERROR:g}",
                    "PASS" if d.error <= TARGET_ERROR else "FAIL",
                )
            )
            out.append(
                TargetCheck(
                    "real-time factor of the default",
                    sb.scene,
                    f"{d.rtf:.1f}x",
                    f">= {TARGET_RTF:g}x",
                    "PASS" if d.rtf >= TARGET_RTF else "FAIL",
                    f"median wall {d.wall * 1e3:.2f} ms for {d.outcome.sim_time:.3f} s "
                    f"simulated; on CPU time {d.rtf_cpu:.1f}x",
                )
            )
        if sb.peers is not None:
            out += _speedup_checks(sb, sb.peers, "compiled peer", TARGET_PEER_SPEEDUP)
        out += _speedup_checks(sb, sb.baselines, "SciPy", TARGET_SPEEDUP)
        if sb.scene in EVENT_SCENES:
            out.append(
                TargetCheck(
                    "stiff-fence event (as loaded)",
                    sb.scene,
                    f"{d.wall * 1e3:.2f} ms",
                    f"<= {TARGET_EVENT_S * 1e3:g} ms",
                    "PASS" if d.wall <= TARGET_EVENT_S else "FAIL",
                    f"median of {len(d.walls)}, model build included",
                )
            )
    return out


def run_bench(
    scenes: Sequence[str] = SCENES,
    repeats: int = 15,
    methods: Sequence[str] = SCIPY_METHODS,
    ladder: Sequence[float] = RTOL_LADDER,
    cap: float = SCIPY_CAP_S,
    quick: bool = False,
    command: str = "python -m benchmarks bench",
    log: Log = _quiet,
    peer_methods: Sequence[str] = PEER_METHODS,
) -> BenchReport:
    """Benchmark ``scenes``; see the module docstring for what is measured and how."""
    t0 = time.perf_counter()
    started = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    load_before = load_average()
    results = []
    for name in scenes:
        results.append(bench_scene(name, repeats, methods, ladder, cap, log, peer_methods))
    jit = jit_comparison(
        max(2, repeats if quick else JIT_REPEATS),
        1 if quick else NOJIT_REPEATS,
        cold=not quick,
        log=log,
    )
    report = BenchReport(
        command=command,
        started=started,
        finished=datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        commit=git_revision(),
        machine=machine_info(),
        load_before=load_before,
        load_after=load_average(),
        options={
            "scenes": list(scenes),
            "repeats": repeats,
            "scipy_methods": list(methods),
            "peer_methods": list(peer_methods),
            "rtol_ladder": list(ladder),
            "scipy_cap_s": cap,
            "quick": quick,
        },
        scenes=results,
        jit=jit,
        process_max_rss_kib=peak_rss_kib(),
        total_wall=time.perf_counter() - t0,
    )
    report.targets = evaluate_targets(results)
    return report


# -- JSON -----------------------------------------------------------------------------------------
def report_dict(report: BenchReport) -> dict:
    """The report as plain JSON data (derived figures such as medians included)."""
    d = dc.asdict(report)
    for sd, sb in zip(d["scenes"], report.scenes, strict=True):
        df = sd["default"]
        df.update(wall=sb.default.wall, cpu=sb.default.cpu, rtf=sb.default.rtf)
        sd["ours"]["check_change"] = sb.ours.check_change
        sd["scipy_ref"]["check_change"] = sb.scipy_ref.check_change
        sd["scipy_ref"]["distance_to_ours"] = rel_error(sb.scipy_ref.peak, sb.ours.peak)
        for family in ("baselines", "peers"):
            if getattr(sb, family) is None:
                continue
            for key in ("by_ref", "by_self"):
                comp = getattr(getattr(sb, family), key)
                best = comp.best
                sd[family][key]["best"] = (
                    None
                    if best is None
                    else {"method": best.method, "rtol": best.run.rtol, "wall": best.wall}
                )
                sd[family][key]["ratio"] = comp.ratio
        for vd, v in zip(sd["parts"]["variants"], sb.parts.variants, strict=True):
            vd["wall"] = v.wall
    d["jit"].update(
        jit_wall=report.jit.jit_wall, nojit_wall=report.jit.nojit_wall, ratio=report.jit.ratio
    )
    return json_safe(d)


def _from_json(kind, value):
    """``value`` (JSON data) as an instance of the annotated type ``kind``."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (types.UnionType, typing.Union):
        if value is None:
            return math.nan if float in args else None
        (kind,) = [a for a in args if a is not type(None)]
        return _from_json(kind, value)
    if dc.is_dataclass(kind):
        hints = typing.get_type_hints(kind)
        names = {f.name for f in dc.fields(kind) if f.init}
        return kind(**{k: _from_json(hints[k], v) for k, v in value.items() if k in names})
    if origin is list:
        return [_from_json(args[0], v) for v in value]
    if origin is tuple:
        return tuple(_from_json(args[0], v) for v in value)
    if kind is float:
        return math.nan if value is None else float(value)
    return value


def report_from_dict(data: dict) -> BenchReport:
    """The report back from :func:`report_dict`'s JSON (derived figures are recomputed)."""
    return _from_json(BenchReport, data)


# -- markdown -------------------------------------------------------------------------------------
def _ms(s: float) -> str:
    return "n/a" if not math.isfinite(s) else f"{s * 1e3:.2f}"


def _e(x: float) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.1e}"


def _mib(kib: float) -> str:
    return f"{kib / 1024:.0f}"


def _family_table(sc: Sequence[SceneBench], family: str) -> list[str]:
    """The table of a family's (``baselines``: SciPy, ``peers``: compiled) chosen rungs."""
    L: list[str] = []
    add = L.append
    digits = 1 if family == "peers" else 0  # the compiled peers' ratios are a few x
    rows = []
    for s in sc:
        b = getattr(s, family)
        if b is None:
            continue
        for comp in (b.by_self, b.by_ref):
            which = "SciPy ref." if comp.metric == "self" else "our ref."
            thr = f"<= {comp.threshold:.1e}" + (" (1e-3 target)" if comp.relaxed else "")
            if comp.metric == "self" and not math.isfinite(s.scipy_ref.peak):
                why = f"no SciPy reference ({s.scipy_ref.label} did not finish)"
                rows.append((s.scene, which, "n/a", "all", why, "", "", "", "", ""))
                continue
            for c in comp.choices:
                if c.run is None:
                    best_err = min(
                        (
                            (r.err_self if comp.metric == "self" else r.err_ref)
                            for r in b.runs
                            if r.method == c.method and r.ok
                        ),
                        default=math.nan,
                    )
                    capped = any(r.capped for r in b.runs if r.method == c.method)
                    why = "did not reach"
                    if capped:
                        why += f" (capped at {b.cap:g} s)"
                    if math.isfinite(best_err):
                        why += f"; best error {best_err:.1e}"
                    rows.append((s.scene, which, thr, c.method, why, "", "", "", "", ""))
                    continue
                r = c.run
                err = r.err_self if comp.metric == "self" else r.err_ref
                best = comp.best is c
                nxt = b.next_rung(r)
                if nxt is None:
                    nxt_err = "not run"
                else:
                    e2 = nxt.err_self if comp.metric == "self" else nxt.err_ref
                    nxt_err = _e(e2) if nxt.ok else "failed"
                    if nxt.ok and math.isfinite(e2) and e2 > comp.threshold:
                        nxt_err += " (not sustained)"
                rows.append(
                    (
                        s.scene,
                        which,
                        thr,
                        f"**{c.method}**" if best else c.method,
                        f"rtol {r.rtol:g}",
                        _e(err),
                        nxt_err,
                        f"{r.outcome.steps}",
                        _ms(c.wall),
                        f"{c.wall / s.default.wall:.{digits}f}x"
                        + (f" ({c.note})" if c.note else ""),
                    )
                )
    L += table(
        (
            "scene",
            "error vs",
            "same error",
            "method",
            "loosest rung reaching it",
            "its error",
            "error at the next tighter rung",
            "steps",
            "wall median [ms]",
            "wall / default's",
        ),
        rows,
    )
    add("")
    return L


def render_markdown(rep: BenchReport) -> str:
    sc = rep.scenes
    L: list[str] = []
    add = L.append
    add("# Benchmarks")
    add("")
    add(
        f"Generated by `{rep.command}` (the file is overwritten on every run; nothing here is "
        "edited by hand). Started {start}, finished {end}, {total:.0f} s in all; commit "
        "`{commit}`.".format(
            start=rep.started, end=rep.finished, total=rep.total_wall, commit=rep.commit
        )
    )
    add("")
    add("## Machine")
    add("")
    rows = [(k, v) for k, v in rep.machine.items()]
    rows.append(
        ("load average (1, 5, 15 min)", f"{rep.load_before} before, {rep.load_after} after")
    )
    L += table(("", ""), rows)
    add("")
    add(
        "How the figures are measured and how to read them: "
        "[verification.md](../design/verification.md#benchmarks)."
    )
    add("")

    add("## Targets")
    add("")
    L += table(
        ("target", "scene", "measured", "limit", "verdict", "note"),
        [
            (t.target, t.scene, t.measured, t.limit, f"**{t.verdict}**", t.note)
            for t in rep.targets
        ],
    )
    add("")

    add("## Default configuration per scene")
    add("")
    rows = []
    for s in sc:
        d = s.default
        rows.append(
            (
                s.scene,
                f"{d.method} rtol {d.rtol:g} dt_max {d.dt_max:g}",
                f"{d.outcome.sim_time:.3f}",
                _ms(d.wall),
                _ms(d.cpu),
                f"{d.rtf:.1f}",
                f"{d.rtf_cpu:.1f}",
                f"{d.outcome.steps} / {d.outcome.rejected}",
                f"{d.outcome.peak_force:.6g}",
                f"{s.ours.peak:.6g}",
                _e(d.error),
                _e(d.exit_speed_diff),
                _ms(d.first_call),
                str(len(d.walls)),
            )
        )
    L += table(
        (
            "scene",
            "method",
            "sim time [s]",
            "wall median [ms]",
            "CPU median [ms]",
            "real-time factor",
            "real-time factor on CPU time",
            "steps / rejected",
            "peak N [N]",
            "reference peak N [N]",
            "rel. error",
            "exit speed diff [m/s]",
            "first call in this process [ms]",
            "repeats",
        ),
        rows,
    )
    add("")

    add("## References")
    add("")
    if sc:
        o, r = sc[0].ours, sc[0].scipy_ref
        add(
            f"Our reference: {o.label}, checked at {o.check_label}. SciPy's: {r.label}, "
            f"checked at {r.check_label}."
        )
        add("")
    rows = []
    for s in sc:
        o, r = s.ours, s.scipy_ref
        rows.append(
            (
                s.scene,
                f"{o.peak:.9g}",
                _e(o.check_change),
                f"{o.wall + o.check_wall:.1f}",
                f"{r.peak:.9g}" if math.isfinite(r.peak) else f"failed: {r.diagnosis}",
                _e(r.check_change),
                f"{r.wall + r.check_wall:.1f}",
                _e(rel_error(r.peak, o.peak)),
                _e(s.belt.gap) if s.belt is not None else "not run",
            )
        )
    L += table(
        (
            "scene",
            "our reference peak N [N]",
            "change at dt / 2",
            "wall [s]",
            "SciPy reference peak N [N]",
            "change at rtol / 10",
            "wall [s]",
            "SciPy ref. vs ours",
            "the same with conveyor.mu_belt = 0",
        ),
        rows,
    )
    add("")
    if any(s.peers is not None for s in sc):
        add("## Compiled peers at the same error")
        add("")
        add(
            "CyRK's C++ solvers (`cyrk:*`, fence_sorter/physics/peers.py) on the same compiled "
            "right-hand side, every accepted step observed by the loop's reductions, restarts "
            "at t1 and 2 t1 and at the belt-edge crossing (found from the accepted steps); the "
            "same rtol ladder and search as the SciPy baselines below."
        )
        add("")
        L += _family_table(sc, "peers")
    add("## SciPy baselines at the same error")
    add("")
    add(
        "rtol ladder "
        f"{', '.join(f'{x:g}' for x in rep.options['rtol_ladder'])}; every SciPy run capped at "
        f"{rep.options['scipy_cap_s']:g} s of wall time."
    )
    add("")
    L += _family_table(sc, "baselines")
    add("Every ladder run (one run each; the wall time of a single run):")
    add("")
    rows = []
    for s in sc:
        for r in (*(s.peers.runs if s.peers is not None else ()), *s.baselines.runs):
            state = "capped" if r.capped else ("ok" if r.outcome.success else "failed")
            if r.capped:
                state += f" at t = {r.outcome.sim_time:.3f} s"
            elif not r.outcome.success:
                state += f": {r.outcome.diagnosis}"
            rows.append(
                (
                    s.scene,
                    r.method,
                    f"{r.rtol:g}",
                    f"{r.wall:.3f}",
                    str(r.outcome.steps),
                    _e(r.err_ref),
                    _e(r.err_self),
                    state,
                )
            )
    L += table(
        (
            "scene",
            "method",
            "rtol",
            "wall [s]",
            "steps",
            "error vs our ref.",
            "error vs SciPy ref.",
            "status",
        ),
        rows,
    )
    add("")

    ev = [s for s in sc if s.scene in EVENT_SCENES]
    if ev:
        add("## Stiff-fence events (optimisation inner loop)")
        add("")
        add(
            "One sorting event on the stiff fence, stopped when sorted (as the scenes are "
            "loaded), model build included; the second column records nothing (what an "
            f"optimisation loop needs). Target <= {TARGET_EVENT_S * 1e3:g} ms per event."
        )
        add("")
        rows = []
        for s in ev:
            lean = s.parts.get("leaner")
            rows.append(
                (
                    s.scene,
                    _ms(s.default.wall),
                    _ms(lean.wall) if lean else "n/a",
                    f"{s.default.outcome.steps}",
                    f"{s.default.outcome.sim_time:.3f}",
                    "PASS" if s.default.wall <= TARGET_EVENT_S else "FAIL",
                )
            )
        L += table(
            (
                "scene",
                "ms per event (as loaded)",
                "ms per event (no recording)",
                "steps",
                "sim time [s]",
                "target",
            ),
            rows,
        )
        add("")

    add("## Peak memory")
    add("")
    rows = [
        (
            s.scene,
            f"{s.memory.tracemalloc_peak / 1024:.0f}",
            _mib(s.memory.rss_after_import_kib),
            _mib(s.memory.rss_after_run_kib),
        )
        for s in sc
    ]
    L += table(
        (
            "scene",
            "tracemalloc peak of one run [KiB]",
            "fresh process max RSS after imports [MiB]",
            "... after one event [MiB]",
        ),
        rows,
    )
    add("")
    add(
        f"The bench process itself (every run above, SciPy included; every accepted step "
        f"of a run is observed and the scenes record time series) peaked at "
        f"{_mib(rep.process_max_rss_kib)} MiB resident."
    )
    add("")

    add("## Model parts: what each scene leaves out")
    add("")
    rows = []
    for s in sc:
        built = s.parts.get("built")
        for v in s.parts.variants:
            added = [p for p in v.parts if p not in built.parts]
            dropped = [p for p in built.parts if p not in v.parts]
            diff = " ".join(["+" + p for p in added] + ["-" + p for p in dropped]) or "(built)"
            if v.same_physics:
                physics = "yes"
            elif v.role == "truncated":
                physics = "approximation (fewer modes)"
            else:
                physics = "no (rigid fence -> flexible)"
            rows.append(
                (
                    s.scene,
                    v.label,
                    physics,
                    diff,
                    _ms(v.wall),
                    f"{v.wall / built.wall:.2f}",
                    f"{v.outcome.steps}",
                    f"{v.outcome.peak_force:.6g}",
                    _e(rel_error(v.outcome.peak_force, built.outcome.peak_force)),
                    f"{v.outcome.exit_speed:.6f}",
                    "yes" if v.outcome.sorted else "no",
                )
            )
    L += table(
        (
            "scene",
            "variant",
            "same physics",
            "parts vs built",
            "wall median [ms]",
            "/ built",
            "steps",
            "peak N [N]",
            "peak vs built",
            "exit speed [m/s]",
            "sorted",
        ),
        rows,
    )
    add("")
    rows = []
    for s in sc:
        built, full = s.parts.get("built"), s.parts.get("full")
        if full is None:
            continue
        saved = full.wall - built.wall
        rows.append(
            (
                s.scene,
                _ms(built.wall),
                _ms(full.wall),
                f"{saved * 1e3:+.2f} ms ({saved / full.wall * 100:+.0f} %)",
                _e(rel_error(full.outcome.peak_force, built.outcome.peak_force)),
                _e(abs(full.outcome.exit_speed - built.outcome.exit_speed)),
                "yes" if full.outcome.sorted == built.outcome.sorted else "no",
            )
        )
    if rows:
        add("Built against the full model (nothing left out):")
        add("")
        L += table(
            (
                "scene",
                "built [ms]",
                "full [ms]",
                "time saved by the built model",
                "peak N difference",
                "exit speed difference [m/s]",
                "same sorted outcome",
            ),
            rows,
        )
        add("")

    j = rep.jit
    add("## Compiled kernel: the same code with and without the JIT")
    add("")
    add(
        f"`{j.scene}` with `--set solver.t_end={j.t_end:g}` ({j.steps} steps, "
        f"{j.sim_time:.3f} s simulated), the same script in two fresh processes: one as usual, "
        "one with `NUMBA_DISABLE_JIT=1` (the kernel's functions then run as plain Python, "
        "the code unchanged). Each process makes one untimed first call, then the timed ones."
    )
    add("")
    L += table(
        ("", "JIT (Numba)", "NUMBA_DISABLE_JIT=1"),
        [
            ("wall median [ms]", _ms(j.jit_wall), _ms(j.nojit_wall)),
            ("timed calls", str(len(j.jit_walls)), str(len(j.nojit_walls))),
            (
                "real-time factor",
                f"{j.sim_time / j.jit_wall:.1f}",
                f"{j.sim_time / j.nojit_wall:.2f}",
            ),
            ("peak N [N]", f"{j.jit_peak:.9g}", f"{j.nojit_peak:.9g}"),
        ],
    )
    add("")
    confirmed = (
        "both child processes reported the JIT state asked for"
        if j.jit_child_confirmed
        else "WARNING: the child processes did not report the JIT state asked for"
    )
    add(
        f"Without the JIT the same run takes **{j.ratio:.0f}x** as long ({confirmed}; the peak "
        f"forces differ by {_e(rel_error(j.nojit_peak, j.jit_peak))})."
    )
    if math.isfinite(j.cold_first_call):
        add(
            f"Compilation: the first call of `{j.cold_scene}` (full scene) in a fresh process "
            f"with an empty Numba cache (`NUMBA_CACHE_DIR` pointing to a new directory) took "
            f"{j.cold_first_call:.1f} s, the second {_ms(j.cold_second_call)} ms; with the "
            f"on-disk cache the first call of the shortened run took "
            f"{_ms(j.warm_cache_first_call)} ms."
        )
    else:
        add(
            f"With the on-disk cache the first call of the shortened run took "
            f"{_ms(j.warm_cache_first_call)} ms (cold compilation not measured in this run)."
        )
    add("")

    add(
        "What these figures mean: "
        "[docs/design/verification.md](../design/verification.md#benchmarks)."
    )
    return "\n".join(L).rstrip() + "\n"
