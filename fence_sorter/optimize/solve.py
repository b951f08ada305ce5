"""Maximise W_t (1) over X = [R_s, v, t1, R_z] subject to (7)-(12) on the twin.

The search is SciPy's differential evolution (global, derivative-free, seeded) on a
feasibility-first energy: a feasible X scores -W_t (< 0), an infeasible one the sum of its
normalised constraint violations (>= 0), so any feasible point beats any infeasible one and
infeasible points are ranked by how far they are from feasibility (Deb's rules in one scalar).
W_t (1), Delta_c (2) and (7) are closed-form: a point violating (7) is scored without running
the twin. The population of a generation is evaluated in chunks on a concurrent.futures
executor (processes, or a Dask cluster: same code). No gradient polish (the twin's response is
not smooth in X: contact onsets and stage switches move with it); instead a short compass search
from the best feasible point walks to the constraint boundary along the directions in which
W_t (1) grows. Every evaluation is cached; the answer is always an evaluated feasible point.
"""

from __future__ import annotations

import concurrent.futures
import functools
import itertools
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import differential_evolution

from fence_sorter.capacity.constraints import CONSTRAINT_TEXT, violated
from fence_sorter.capacity.evaluate import evaluate_stroke, planning_scenario
from fence_sorter.capacity.formulas import pitch
from fence_sorter.jsonsafe import json_safe
from fence_sorter.optimize.problem import UNITS, VARIABLES, OptimizeSpec
from fence_sorter.optimize.restarts import restart_spread
from fence_sorter.physics.params import ParameterError
from fence_sorter.scene import load_scene

#: normalisation of each constraint's violation in the energy (its natural scale)
SCALES = {7: 1.0, 8: 0.7, 9: 1.0}
#: a constraint is reported active when its margin is in [-tol, 0]; tol as a fraction of the
#: scale (7)-(9) above, or of the limit w_dop, a_Ndop, ydot_dop for (10)-(12)
ACTIVE_TOL = 0.03
#: energy of a point the twin could not evaluate (solver failure) or left unevaluated
FAILED_PENALTY = 10.0
#: share of the budget for differential evolution; the rest is for the compass search
DE_SHARE = 0.85
#: compass search: first step as a fraction of each range, steps halved down to this fraction
REFINE_STEP = 0.08
REFINE_MIN_STEP = 0.005
#: a variable within this fraction of its range of a bound is reported at that bound
AT_BOUND_TOL = 0.01


# -- one twin evaluation -------------------------------------------------------------------
@functools.lru_cache(maxsize=4)
def _base_scenario(fence: str):
    """The planning scenario (stiff fence, loose tolerances, stop when sorted) of the
    positioned_stiff scene, or of it with the flexible PA6 fence of impact_flexible."""
    base = load_scene("positioned_stiff").scenario
    if fence == "flexible":
        flex = load_scene("impact_flexible").scenario
        base = replace(base, fence=flex.fence, fence_modes=flex.fence_modes)
        return planning_scenario(base, fence="scene")
    return planning_scenario(base, fence="stiff")


def _scenario_for(spec: OptimizeSpec, v: float, r_z: float):
    base = _base_scenario(spec.fence)
    base = replace(base, conveyor=replace(base.conveyor, belt_speed=v, width=spec.belt_width))
    if base.fence is not None:
        return replace(base, fence=replace(base.fence, length=r_z))
    return replace(base, fence_length=r_z)


def closed_form(spec: OptimizeSpec, X: dict[str, float]) -> tuple[float, float, float]:
    """(W_t (1) [pcs/h], Delta_c (2) [m], margin of (7) [s]) of X; no simulation."""
    a = spec.a_max()
    delta_c = pitch(X["v"], X["t1"], X["R_s"], a, spec.gap)
    return 3600.0 * X["v"] / delta_c, delta_c, (a - X["R_s"]) / X["v"] - X["t1"]


def evaluate_point(spec: OptimizeSpec, X: dict[str, float]) -> dict:
    """One twin evaluation of X: every load of the case (both C_s positions of Fig. 2), the
    worse margin of each constraint; (9) from the minimal object in the arbitrary case.

    Returns a dict: feasible, W_t [pcs/h], Delta_c [m], margins {constraint: margin},
    violated, simulated (False when (7) alone rejected X), loads {name: diagnosis}.
    """
    w_t, delta_c, m7 = closed_form(spec, X)
    out = {
        "X": {k: float(X[k]) for k in VARIABLES},
        "W_t": w_t,
        "Delta_c": delta_c,
        "margins": {7: m7},
        "simulated": False,
        "loads": {},
    }
    if 7 in spec.constraints and m7 > 0.0:
        out.update(feasible=False, violated=[7])
        return out
    profile = spec.profile()
    sc = _scenario_for(spec, X["v"], X["R_z"])
    per_load: dict[str, dict[int, float]] = {}
    for name, parcel in spec.loads():
        ev = evaluate_stroke(
            sc,
            parcel,
            X["R_s"],
            X["t1"],
            spec.alpha_k,
            profile,
            gap=spec.gap,
            a_max=spec.a_max(),
            mu_belt=spec.mu1,
            mu_fence=spec.mu2,
        )
        per_load[name] = ev.margins
        out["loads"][name] = ev.diagnosis
    margins = {7: m7}
    for c in (8, 9, 10, 11, 12):
        names = list(per_load)
        if c == 9 and spec.case == "arbitrary":
            # T_g relates to the minimal object on the far side (section 3, below (12))
            names = [n for n in names if n.startswith("minimal")]
        vals = [per_load[n].get(c, math.nan) for n in names]
        if c == 12:
            vals = [m for m in vals if not math.isnan(m)]  # NaN: not sorted, (8) reports it
            margins[c] = max(vals) if vals else math.nan
        else:
            margins[c] = math.nan if any(math.isnan(m) for m in vals) else max(vals)
    bad = list(violated(margins, spec.constraints))
    out.update(margins=margins, simulated=True, feasible=not bad, violated=bad)
    return out


def _evaluate_chunk(spec: OptimizeSpec, points: Sequence[dict[str, float]]) -> list[dict]:
    """Evaluate several points in one task (a worker process or a Dask worker)."""
    return [evaluate_point(spec, X) for X in points]


# -- result ----------------------------------------------------------------------------------
@dataclass
class OptimumResult:
    """The optimum found (or why there is none)."""

    feasible: bool
    X: dict[str, float]  # R_s [m], v [m/s], t1 [s], R_z [m]
    W_t: float  # (1) [pcs/h]
    Delta_c: float  # (2) [m]
    active: list[int]  # margin within ACTIVE_TOL of 0, or violated by a W_t-raising step
    margins: dict[int, float]
    infeasible: str | None
    evaluations: int  # twin evaluations (points simulated)
    wall_time: float  # [s]
    spec: dict
    at_bounds: dict[str, str] = field(default_factory=dict)  # variable -> "low" | "high"
    # constraints violated a small step away in each direction that raises W_t ("R_s-": [8])
    blocking: dict[str, list[int]] = field(default_factory=dict)
    points: int = 0  # points scored (twin evaluations + closed-form rejections by (7))
    history: list[dict] = field(default_factory=list)  # best W_t per generation
    # best W_t [pcs/h] each restart reached, differential evolution and its compass search
    # (NaN: none feasible): their spread shows how sure the answer is
    restarts: list[float] = field(default_factory=list)

    def to_dict(self) -> dict:
        return json_safe(
            {
                "feasible": self.feasible,
                "X": dict(self.X),
                "W_t": self.W_t,
                "Delta_c": self.Delta_c,
                "active": list(self.active),
                "margins": {int(k): v for k, v in sorted(self.margins.items())},
                "at_bounds": dict(self.at_bounds),
                "blocking": dict(self.blocking),
                "infeasible": self.infeasible,
                "evaluations": self.evaluations,
                "points": self.points,
                "restarts": list(self.restarts),
                "restart_spread": restart_spread(self.restarts),
                "wall_time": self.wall_time,
                "spec": self.spec,
            }
        )


# -- the search ------------------------------------------------------------------------------
def energy(spec: OptimizeSpec, r: dict) -> float:
    """Feasibility-first score of an evaluation: -W_t if feasible, else the sum of the
    normalised violations (>= 0; FAILED_PENALTY per constraint the twin could not judge)."""
    if r["feasible"]:
        return -r["W_t"]
    if not r["simulated"]:
        return 1.0 + r["margins"][7] / SCALES[7]  # (7) violated; the rest is unknown
    total = 0.0
    for c in spec.constraints:
        m = r["margins"].get(c, math.nan)
        if c == 12 and math.isnan(m):
            continue
        if math.isnan(m):
            total += FAILED_PENALTY
        elif m > 0.0:
            total += m / _scale(spec, c)
    return total


def _scale(spec: OptimizeSpec, c: int) -> float:
    return {10: spec.w_dop, 11: spec.a_ndop, 12: spec.exit_speed_limit}.get(c) or SCALES[c]


class _Evaluator:
    """Cached, batched evaluation of points on an executor (or in this process)."""

    def __init__(self, spec: OptimizeSpec, executor: concurrent.futures.Executor | None):
        self.spec = spec
        self.executor = executor
        self.cache: dict[tuple[float, ...], dict] = {}
        self.evaluations = 0
        self.chunks = _parallelism(executor) * 2

    def key(self, X: dict[str, float]) -> tuple[float, ...]:
        return tuple(round(float(X[k]), 12) for k in VARIABLES)

    def batch(self, points: Sequence[dict[str, float]]) -> list[dict]:
        todo: dict[tuple, dict] = {}
        for X in points:
            k = self.key(X)
            if k in self.cache or k in todo:
                continue
            _, _, m7 = closed_form(self.spec, X)
            if 7 in self.spec.constraints and m7 > 0.0:
                self.cache[k] = evaluate_point(self.spec, X)  # closed form, no twin
            else:
                todo[k] = X
        if todo:
            keys = list(todo)
            pts = [todo[k] for k in keys]
            if self.executor is None:
                results = _evaluate_chunk(self.spec, pts)
            else:
                n = max(1, math.ceil(len(pts) / self.chunks))
                futures = [
                    self.executor.submit(_evaluate_chunk, self.spec, pts[i : i + n])
                    for i in range(0, len(pts), n)
                ]
                results = [r for f in futures for r in f.result()]
            for k, r in zip(keys, results, strict=True):
                self.cache[k] = r
            self.evaluations += len(keys)
        return [self.cache[self.key(X)] for X in points]

    def best_feasible(self) -> dict | None:
        feas = [r for r in self.cache.values() if r["feasible"]]
        if not feas:
            return None
        # highest W_t; ties (R_z does not enter W_t) to the larger smallest normalised slack
        return max(feas, key=lambda r: (round(r["W_t"], 6), self._slack(r)))

    def _slack(self, r: dict) -> float:
        ms = [
            -r["margins"][c] / _scale(self.spec, c)
            for c in self.spec.constraints
            if c != 8 and not math.isnan(r["margins"].get(c, math.nan))
        ]
        return min(ms) if ms else 0.0


def _parallelism(executor) -> int:
    if executor is None:
        return 1
    n = getattr(executor, "_max_workers", None)
    if n:
        return int(n)
    client = getattr(executor, "_client", None)
    if client is not None:
        try:
            return max(1, sum(client.nthreads().values()))
        except Exception:
            return 2
    return 2


def optimize(
    spec: OptimizeSpec,
    executor: concurrent.futures.Executor | None = None,
    starts: Sequence[Mapping[str, float]] = (),
) -> OptimumResult:
    """Maximise W_t (1) for ``spec``; twin evaluations on ``executor`` (None: this process).

    ``starts``: points X (R_s, v, t1, R_z) evaluated before the search; the best feasible one
    replaces the first member of the initial population, so the answer is never below a
    feasible start (a sweep starts a looser problem from a tighter neighbour's optimum, which
    is feasible for it). Deterministic for a given spec (seed) and starts whatever the
    executor. Raises ParameterError for an invalid spec or a start outside the ranges or off
    a fixed value; an infeasible problem returns ``feasible=False`` with the reason.
    """
    spec.validate()
    t0 = time.perf_counter()
    ev = _Evaluator(spec, executor)
    ranges = spec.ranges()
    fixed = spec.fixed_values()
    free = spec.free_variables()
    history: list[dict] = []
    starts = [_check_start(X, ranges, fixed, i) for i, X in enumerate(starts)]

    def full(x: Sequence[float]) -> dict[str, float]:
        X = dict(fixed)
        X.update({n: float(v) for n, v in zip(free, x, strict=True)})
        return X

    why = _closed_form_infeasible(spec, ranges, fixed)
    if why is not None:
        return _result(spec, ev, None, t0, history, why)

    x0 = None
    restart_w: list[float] = []  # best W_t of each restart's differential evolution
    feasible_starts = [r for r in ev.batch(starts) if r["feasible"]]
    if feasible_starts and free:
        best_start = max(feasible_starts, key=lambda r: r["W_t"])
        # a hair inside the box: SciPy rescales x0 to [0, 1] and a value on a bound can land
        # a rounding error outside (the start itself is already evaluated and kept)
        x0 = [
            min(max(best_start["X"][n], lo + 1e-9 * (hi - lo)), hi - 1e-9 * (hi - lo))
            for n in free
            for lo, hi in [ranges[n]]
        ]
    if not free:
        ev.batch([full(())])
    else:
        bounds = [ranges[n] for n in free]
        # ~40 members (10 per variable, at least 20): enough to sample the 4-D box globally
        popsize = max(5, math.ceil(40 / len(free)))
        pop_n = popsize * len(free)
        de_budget = max(pop_n, int(DE_SHARE * spec.budget))

        def objective(x):
            return energy(spec, ev.batch([full(x)])[0])

        def workers(func, xs):
            xs = list(xs)
            ev.batch([full(x) for x in xs])  # in parallel, fills the cache
            return list(map(func, xs))

        stop_at = 0

        # the one parameter must be named intermediate_result: SciPy inspects the signature
        # and calls any other callback as callback(x, convergence)
        def callback(intermediate_result):
            best = ev.best_feasible()
            history.append(
                {"evaluations": ev.evaluations, "W_t": best["W_t"] if best else math.nan}
            )
            return ev.evaluations >= stop_at

        for i in range(spec.restarts):
            restart_end = ev.evaluations + spec.budget
            stop_at = ev.evaluations + de_budget

            res = differential_evolution(
                objective,
                bounds,
                popsize=popsize,
                maxiter=max(1, 4 * spec.budget // pop_n),
                mutation=(0.5, 1.0),
                recombination=0.7,
                tol=1e-3,
                seed=(spec.seed + i) % 2**32,
                polish=False,
                init="sobol" if _pow2(pop_n) else "latinhypercube",
                updating="deferred",
                workers=workers,
                callback=callback,
                x0=x0 if i == 0 else None,
            )
            # each restart's own compass search from its own best: from the best of all only,
            # a restart whose evolution stopped lower but refines higher was lost (arbitrary,
            # 40 deg: 3133 pcs/h against seed 0's 3162 alone)
            found = ev.batch([full(res.x)])[0]
            if found["feasible"]:
                found = _refine(spec, ev, ranges, free, full, restart_end, found)
            restart_w.append(found["W_t"] if found["feasible"] else math.nan)
    return _result(spec, ev, ev.best_feasible(), t0, history, None, restart_w)


def _check_start(
    X: Mapping[str, float], ranges: dict, fixed: dict[str, float], i: int
) -> dict[str, float]:
    """A start point as a plain dict; ParameterError if it misses a variable, lies outside
    the ranges or differs from a fixed value."""
    missing = [n for n in VARIABLES if n not in X]
    if missing:
        raise ParameterError(f"starts[{i}] lacks {', '.join(missing)}; give all of {VARIABLES}")
    out = {n: float(X[n]) for n in VARIABLES}
    for n, v in out.items():
        if n in fixed:
            if abs(v - fixed[n]) > 1e-12 * max(1.0, abs(fixed[n])):
                raise ParameterError(
                    f"starts[{i}].{n} = {v:g} differs from the fixed {fixed[n]:g}"
                )
            continue
        lo, hi = ranges[n]
        if not lo <= v <= hi:
            raise ParameterError(
                f"starts[{i}].{n} = {v:g} {UNITS[n]} outside its range [{lo:g}, {hi:g}]"
            )
    return out


def _pow2(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


def _refine(spec, ev: _Evaluator, ranges, free, full, budget: int, best: dict) -> dict:
    """Compass search from the feasible evaluation ``best`` until ``budget`` evaluations in
    all: poll, in parallel, every move of the 3^k - 1 pattern {-1, 0, 1}^k x step (k free
    variables; R_z included: W_t ignores it, the constraints do not) that raises W_t (1); move
    to the best feasible poll point, else halve the step. Moves of several variables at once
    follow a constraint boundary that is oblique to the axes. Returns the point it ends on."""
    step = REFINE_STEP
    while step >= REFINE_MIN_STEP and ev.evaluations < budget:
        polls = _polls(spec, best, ranges, free, step)
        if not polls:
            break
        # best W_t first, within what is left of the budget
        polls.sort(key=lambda X: -closed_form(spec, X)[0])
        polls = polls[: max(1, budget - ev.evaluations)]
        res = [r for r in ev.batch(polls) if r["feasible"] and r["W_t"] > best["W_t"]]
        if res:
            best = max(res, key=lambda r: (r["W_t"], ev._slack(r)))
        else:
            step *= 0.5
    return best


def _polls(spec, best, ranges, free, step) -> list[dict[str, float]]:
    """The moves around ``best`` by ``step`` (a fraction of each range) that raise W_t (1)."""
    x0 = best["X"]
    out = []
    for signs in itertools.product((-1.0, 0.0, 1.0), repeat=len(free)):
        if not any(signs):
            continue
        X = dict(x0)
        for n, s in zip(free, signs, strict=True):
            lo, hi = ranges[n]
            X[n] = min(hi, max(lo, x0[n] + s * step * (hi - lo)))
        if X != x0 and closed_form(spec, X)[0] > best["W_t"] * (1.0 + 1e-9):
            out.append(X)
    return out


def _blocking(spec, ev: _Evaluator, best, ranges, free) -> dict[str, list[int]]:
    """Constraints violated one finest step (REFINE_MIN_STEP) away from ``best`` in each
    single-variable direction that raises W_t (1): what stops the capacity from growing.
    This is how (8) shows up: a sorted load's margin of (8) is 0 by construction."""
    x0 = best["X"]
    probes = {}
    for n in free:
        lo, hi = ranges[n]
        for s in (-1.0, 1.0):
            X = dict(x0)
            X[n] = min(hi, max(lo, x0[n] + s * REFINE_MIN_STEP * (hi - lo)))
            if X != x0 and closed_form(spec, X)[0] > best["W_t"] * (1.0 + 1e-9):
                probes[f"{n}{'+' if s > 0 else '-'}"] = X
    results = ev.batch(list(probes.values()))
    return {k: list(r["violated"]) for k, r in zip(probes, results, strict=True)}


def _closed_form_infeasible(spec, ranges, fixed) -> str | None:
    """The reason when (7) fails on the whole box (it is monotone in each variable, so its
    smallest value is at a corner of the (R_s, v, t1) box); None if some point may meet it."""
    if 7 not in spec.constraints:
        return None
    box = [[fixed[n]] if n in fixed else list(ranges[n]) for n in ("R_s", "v", "t1")]
    a = spec.a_max()
    best = min((a - r_s) / v - t1 for r_s, v, t1 in itertools.product(*box))
    if best > 0.0:
        return (
            f"infeasible: {CONSTRAINT_TEXT[7]} cannot be met anywhere in the ranges "
            f"(smallest margin {best:.3g} s at the corner of R_s, v, t1 with A = {a:g} m)"
        )
    return None


def _infeasible_reason(spec: OptimizeSpec, ev: _Evaluator) -> str:
    results = list(ev.cache.values())
    sims = [r for r in results if r["simulated"]]
    if not sims:
        best7 = min(r["margins"][7] for r in results)
        return (
            f"infeasible: {CONSTRAINT_TEXT[7]} not met at any of {len(results)} evaluated "
            f"points (smallest margin {best7:.3g} s)"
        )
    never = []
    for c in spec.constraints:
        ms = [r["margins"].get(c, math.nan) for r in sims]
        if not any(_met(c, m) for m in ms):
            never.append(f"{CONSTRAINT_TEXT[c]} not met (smallest margin {_low(ms)})")
    n = len(sims)
    if never:
        return f"infeasible: at {n} simulated points: " + "; ".join(never)
    # each constraint is met somewhere: name those that fail wherever all the others hold
    blockers = []
    for c in spec.constraints:
        others = [
            r
            for r in sims
            if all(_met(o, r["margins"].get(o, math.nan)) for o in spec.constraints if o != c)
        ]
        if others:
            ms = [r["margins"].get(c, math.nan) for r in others]
            rest = ", ".join(f"({o})" for o in spec.constraints if o != c)
            blockers.append(
                f"{CONSTRAINT_TEXT[c]} not met at any of the {len(others)} points that meet "
                f"{rest} (smallest margin there {_low(ms)})"
            )
    if blockers:
        return "infeasible: " + "; ".join(blockers)
    cons = ", ".join(f"({c})" for c in spec.constraints)
    return f"infeasible: each of {cons} is met somewhere, but no two together at any of {n} points"


def _met(c: int, m: float) -> bool:
    return m <= 0.0 or (c == 12 and math.isnan(m))


def _low(ms) -> str:
    finite = [m for m in ms if math.isfinite(m)]
    return f"{min(finite):.3g}" if finite else "n/a"


def _result(spec, ev: _Evaluator, best, t0, history, why, restart_w=()) -> OptimumResult:
    wall = time.perf_counter() - t0
    common = dict(
        evaluations=ev.evaluations,
        points=len(ev.cache),
        wall_time=wall,
        spec=spec.to_dict(),
        history=history,
        restarts=list(restart_w),
    )
    if best is None:
        return OptimumResult(
            feasible=False,
            X={},
            W_t=math.nan,
            Delta_c=math.nan,
            active=[],
            margins={},
            infeasible=why or _infeasible_reason(spec, ev),
            **common,
        )
    ranges = spec.ranges()
    blocking = _blocking(spec, ev, best, ranges, spec.free_variables())
    common["evaluations"] = ev.evaluations
    common["points"] = len(ev.cache)
    margins = {c: best["margins"].get(c, math.nan) for c in spec.constraints}
    active = sorted({c for cs in blocking.values() for c in cs})
    for c, m in margins.items():
        if c == 8:
            continue  # a sorted load's (8) margin is 0 by construction (the run stops there)
        if math.isfinite(m) and -ACTIVE_TOL * _scale(spec, c) <= m <= 0.0:
            active.append(c)
    active = sorted(set(active))
    at_bounds = {}
    for n in spec.free_variables():
        lo, hi = ranges[n]
        tol = AT_BOUND_TOL * (hi - lo)
        if best["X"][n] <= lo + tol:
            at_bounds[n] = "low"
        elif best["X"][n] >= hi - tol:
            at_bounds[n] = "high"
    return OptimumResult(
        feasible=True,
        X=dict(best["X"]),
        W_t=best["W_t"],
        Delta_c=best["Delta_c"],
        active=active,
        margins=margins,
        infeasible=None,
        at_bounds=at_bounds,
        blocking=blocking,
        **common,
    )


#: default grid steps of :func:`grid_search` [m, m/s, s, m]
GRID_STEPS = {"R_s": 0.05, "v": 0.1, "t1": 0.05, "R_z": 0.025}


def grid_axes(spec: OptimizeSpec, steps: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    """The grid of each free variable: its range in steps of ``steps`` (both ends included)."""
    steps = {**GRID_STEPS, **(steps or {})}
    ranges = spec.ranges()
    axes = {}
    for n in spec.free_variables():
        lo, hi = ranges[n]
        k = max(1, round((hi - lo) / steps[n]))
        axes[n] = np.linspace(lo, hi, k + 1) if hi > lo else np.array([lo])
    return axes


def grid_search(
    spec: OptimizeSpec,
    steps: dict[str, float] | None = None,
    executor: concurrent.futures.Executor | None = None,
    batch: int = 256,
) -> dict:
    """The best feasible point of a regular grid, exactly: W_t (1) is closed-form, so the grid
    points are visited in descending W_t order (in batches, on ``executor``) and the search
    stops after the batch holding the first feasible point; every point not simulated has a
    W_t no higher. Returns {"best": evaluation or None, "grid_points", "evaluations",
    "points", "wall_time", "steps"}. The yardstick of the optimiser (docs/design/optimize.md)."""
    spec.validate()
    t0 = time.perf_counter()
    axes = grid_axes(spec, steps)
    fixed = spec.fixed_values()
    # W_t (1) does not depend on R_z: order the (R_s, v, t1) triples, expand each with every R_z
    wvars = ("R_s", "v", "t1")
    grids = [axes[n] if n in axes else np.array([fixed[n]]) for n in wvars]
    r_s, v, t1 = (m.ravel() for m in np.meshgrid(*grids, indexing="ij"))
    r_z = axes["R_z"] if "R_z" in axes else np.array([fixed["R_z"]])
    size = r_s.size * r_z.size
    a = spec.a_max()
    vt_z = v * (2.0 * t1 + np.abs(r_s) / v)
    delta_c = np.where(vt_z > a + spec.gap, vt_z, a + spec.gap)
    w_t = 3600.0 * v / delta_c
    keep = np.ones(r_s.size, bool)
    if 7 in spec.constraints:
        keep = (a - r_s) / v - t1 <= 0.0
    order = np.flatnonzero(keep)[np.argsort(-w_t[keep], kind="stable")]
    ev = _Evaluator(spec, executor)
    best = None
    pending: list[dict[str, float]] = []

    def flush() -> dict | None:
        feas = [r for r in ev.batch(pending) if r["feasible"]]
        pending.clear()
        return max(feas, key=lambda r: r["W_t"]) if feas else None

    for j in order:
        for z in r_z:
            pending.append(
                {"R_s": float(r_s[j]), "v": float(v[j]), "t1": float(t1[j]), "R_z": float(z)}
            )
        if len(pending) >= batch:
            best = flush()
            if best is not None:
                break
    if best is None and pending:
        best = flush()
    return {
        "best": best,
        "grid_points": int(size),
        "evaluations": ev.evaluations,
        "points": len(ev.cache),
        "wall_time": time.perf_counter() - t0,
        "steps": {n: float(axes[n][1] - axes[n][0]) if len(axes[n]) > 1 else 0.0 for n in axes},
    }
