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

import gc
import math
import time
import tracemalloc
from collections.abc import Sequence
from datetime import UTC, datetime

from benchmarks.bench_baselines import (
    BaselineResult,
    Comparison,
    LadderRun,
    _comparisons,
    _loosest,
    ladder_search,
    search_rungs,
)
from benchmarks.bench_children import MemoryResult, jit_comparison, peak_rss_kib, run_child
from benchmarks.bench_parts import model_parts
from benchmarks.bench_report import (
    BeltProbe,
    BenchReport,
    SceneBench,
    TargetCheck,
    render_markdown,
    report_dict,
    report_from_dict,
)
from benchmarks.bench_runs import (
    ATOL_FACTOR,
    BASELINE_REPEATS,
    EVENT_SCENES,
    JIT_REPEATS,
    NOJIT_REPEATS,
    PARTS_ROUNDS,
    PEER_METHODS,
    QUICK_PEER_METHODS,
    QUICK_RTOL_LADDER,
    QUICK_SCENES,
    QUICK_SCIPY_METHODS,
    REFERENCE_DT,
    RETIME_FACTOR,
    RTOL_LADDER,
    SCENES,
    SCIPY_CAP_S,
    SCIPY_REFERENCE,
    TARGET_ERROR,
    TARGET_EVENT_S,
    TARGET_PEER_SPEEDUP,
    TARGET_RTF,
    TARGET_RTF_SCENES,
    TARGET_SPEEDUP,
    DefaultResult,
    Log,
    _quiet,
    collect,
    our_reference,
    reference_solver,
    rel_error,
    scipy_reference,
    timed_run,
    with_solver,
)
from fence_sorter.physics.params import SCIPY_METHODS
from fence_sorter.scene import load_scene
from fence_sorter.verification.machine import git_revision, load_average, machine_info

# -- the whole bench ------------------------------------------------------------------------------


def belt_probe(name: str, cap: float) -> BeltProbe:
    sc = load_scene(name, ["conveyor.mu_belt=0"]).scenario
    method, rtol = SCIPY_REFERENCE
    a, _, _ = timed_run(reference_solver(sc, REFERENCE_DT))
    b, _, _ = timed_run(
        with_solver(sc, method=method, rtol=rtol, atol=rtol * ATOL_FACTOR, max_wall_time=cap)
    )
    return BeltProbe(a.peak_force, b.peak_force if b.success else math.nan)


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


#: the campaign and, for its command and tests, the names of its parts they use
__all__ = [
    "PEER_METHODS",
    "QUICK_PEER_METHODS",
    "QUICK_RTOL_LADDER",
    "QUICK_SCENES",
    "QUICK_SCIPY_METHODS",
    "_loosest",
    "belt_probe",
    "bench_scene",
    "evaluate_targets",
    "LadderRun",
    "render_markdown",
    "report_dict",
    "report_from_dict",
    "run_bench",
    "search_rungs",
]
