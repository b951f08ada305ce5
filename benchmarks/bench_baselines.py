"""The baselines of the speed bench, compiled peers (``cyrk:*``) and SciPy alike: the rtol
ladder searched per method, the rungs that reach the default's error confirmed and re-timed,
the fastest of each family compared with the default (see :mod:`benchmarks.bench`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from benchmarks.bench_runs import (
    ATOL_FACTOR,
    RETIME_FACTOR,
    TARGET_ERROR,
    Log,
    Outcome,
    _median,
    _quiet,
    collect,
    rel_error,
    timed_run,
    with_solver,
)


# -- baselines: compiled peers and SciPy ----------------------------------------------------------
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
