"""Stability campaign: stiff and extreme sorting events, each with a verdict and its invariants.

Every :class:`Case` is a shipped scene plus dotted-key overrides (the same ``key=value`` the CLI's
``--set`` takes) and an expectation:

- ``pass``: the solve succeeds and meets every invariant below;
- ``diagnosed``: the case truly cannot be solved (or is deliberately broken); the solve must stop
  with ``success = False`` and a diagnosis naming the cause, never return garbage;
- ``warning``: the scene loader must warn (e.g. a belt speed beyond the paper's range (4)) and the
  solve must still either pass its invariants or stop with a named diagnosis.

Invariants of a successful solve, each recorded as (name, passed, value, limit):

- ``finite``: every reported number (peaks, y_max, energy, penetration, recorded series) is
  finite; the exit speed is finite exactly when the load was sorted.
- ``energy``: the load's energy E_load = kinetic + sum k_p D^5 / 5 never rises above E_load(0)
  plus the work its power sources did on it (fence surface velocity x contact force, belt velocity
  x belt friction; see ``kernel.observe``). The audit integrates the source power with the
  trapezoidal rule at the accepted points, so it carries a quadrature error of the order of the
  solver's local error times the energy that flowed through the load; the tolerance is therefore
  ``ENERGY_ABS + ENERGY_REL x E_flow`` with E_flow = E_load(0) + integral of |P_sources| dt.
- ``energy_conserved`` (elastic cases only: b_p = 0, mu1 = mu2 = 0, no beam damping): the
  balance holds both ways, |E_load - E_load(0) - W_sources| <= the same tolerance.
- ``penetration``: D_max <= contact.deep_penetration x min(A, B), the solver's own divergence
  limit; the ratio D_max / limit is reported.
- ``convergence``: the case is solved again with the step halved (adaptive: rtol/10, atol/10,
  dt_max/2, first step dt/2; fixed step: dt/2) and the peak contact force, y_max, exit speed and
  sorted flag are compared (tolerances :data:`CONV_FORCE_REL` and friends below).
- ``bounded_time``: the solve's wall time stays below ``solver.max_wall_time`` (plus one step's
  grace); the solver itself stops a longer solve with a wall-time diagnosis, so no case can hang.

The campaign runs from ``fence-sorter stability`` (``fence_sorter/cli/stability.py``), which
writes ``README.md``, ``results.json`` and ``summary.png`` into ``--out`` (this repository's
report: docs/reports/stability/).
"""

from __future__ import annotations

import dataclasses
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fence_sorter.codes import Stage
from fence_sorter.physics.params import ParameterError
from fence_sorter.physics.simulate import EnergyAudit, SortingModel, simulate
from fence_sorter.scene import load_scene
from fence_sorter.verification.stability_cases import (
    DIAGNOSED,
    FAIL,
    KNOWN_CAUSES,
    PASS,
    Case,
    refined_solver,
    refinement_text,
    yaml_value,
)

__all__ = ["CaseResult", "Invariant", "run_case", "run_cases", "warm_up"]

# -- tolerances ---------------------------------------------------------------------------------
ENERGY_ABS = 1e-6  # [J] floor of the energy audit (round-off of E ~ 10 J sums)
ENERGY_REL = 1e-3  # share of the energy flow E_flow the audit's quadrature may miss
CONV_FORCE_REL = 2e-2  # peak contact force: |N_h - N_h/2| <= 2 % of N + ...
CONV_FORCE_ABS_G = 1e-2  # ... 1 % of the load's weight (a grazing touch has N ~ 0)
CONV_Y_ABS = 5e-3  # [m] y_max (when the run did not stop at the sorting line)
CONV_Y_REL = 1e-2
CONV_EXIT_ABS = 2e-2  # [m/s] exit speed ydot at y0 = s
CONV_EXIT_REL = 1e-2
TIME_GRACE = 5.0  # [s] one step past the wall-time check


# -- invariants -----------------------------------------------------------------------------------
@dataclass
class Invariant:
    name: str
    passed: bool
    value: float | str
    limit: float | str
    note: str = ""

    def to_dict(self) -> dict:
        def conv(v):
            if isinstance(v, float) and not math.isfinite(v):
                return str(v)
            return v

        return {
            "name": self.name,
            "passed": self.passed,
            "value": conv(self.value),
            "limit": conv(self.limit),
            "note": self.note,
        }


@dataclass
class CaseResult:
    case: Case
    verdict: str  # PASS | FAIL | DIAGNOSED
    meets_expectation: bool
    invariants: list[Invariant]
    warnings: tuple[str, ...] = ()
    diagnosis: str | None = None
    error: str | None = None  # an exception (a bug, never a diagnosis)
    result: object | None = None  # SimulationResult of the nominal run
    refined: object | None = None  # SimulationResult at the halved step
    audit: EnergyAudit | None = None
    energy_tolerance: float = math.nan
    deep_limit: float = math.nan
    refinement: str = ""
    wall_time: float = 0.0  # both runs, including scene loading

    def invariant(self, name: str) -> Invariant | None:
        return next((i for i in self.invariants if i.name == name), None)

    @property
    def failed_invariants(self) -> list[Invariant]:
        return [i for i in self.invariants if not i.passed]

    def to_dict(self) -> dict:
        def num(v):
            return None if v is None or not math.isfinite(v) else float(v)

        def res(r):
            if r is None:
                return None
            d = r.to_dict()
            d.pop("stages", None)
            d["stages"] = [s for s, _ in r.stages]
            return d

        c = self.case
        return {
            "name": c.name,
            "item": c.item,
            "description": c.description,
            "scene": c.scene,
            "overrides": {k: v for k, v in c.overrides.items()},
            "expected": c.expected,
            "note": c.note,
            "speed": c.speed,
            "max_wall_time_s": c.max_wall_time,
            "verdict": self.verdict,
            "meets_expectation": self.meets_expectation,
            "warnings": list(self.warnings),
            "diagnosis": self.diagnosis,
            "error": self.error,
            "invariants": [i.to_dict() for i in self.invariants],
            "energy": None
            if self.audit is None
            else {
                "max_residual_J": num(self.audit.max_residual),
                "min_residual_J": num(self.audit.min_residual),
                "flow_J": num(self.audit.flow),
                "tolerance_J": num(self.energy_tolerance),
            },
            "deep_limit_m": num(self.deep_limit),
            "refinement": self.refinement,
            "wall_time_s": self.wall_time,
            "result": res(self.result),
            "refined": res(self.refined),
        }


def _finite_check(r) -> Invariant:
    bad = []
    scalars = {
        "peak_contact_force": r.peak_contact_force,
        "peak_contact_force_stiff": r.peak_contact_force_stiff,
        "peak_normal_accel": r.peak_normal_accel,
        "y_max": r.y_max,
        "peak_tip_deflection": r.peak_tip_deflection,
        "energy_excess": r.energy_excess,
        "max_penetration": r.max_penetration,
        "sim_time": r.sim_time,
    }
    bad += [k for k, v in scalars.items() if not math.isfinite(v)]
    if r.sorted != math.isfinite(r.exit_speed_y):
        bad.append("exit_speed_y")
    touched = any(s != Stage.ON_BELT.label for s, _ in r.stages)
    if touched and not math.isfinite(r.impact_normal_speed):
        bad.append("impact_normal_speed")
    bad += [k for k, v in r.series.items() if v.dtype.kind == "f" and not np.isfinite(v).all()]
    bad += [f"impacts[{i}]" for i, imp in enumerate(r.impacts) if not np.isfinite(imp).all()]
    return Invariant(
        "finite",
        not bad,
        "non-finite: " + ", ".join(bad) if bad else "all finite",
        "all finite",
    )


def _rel_close(a: float, b: float, rel: float, floor: float) -> tuple[bool, float, float]:
    """(passed, |a - b|, allowed) for two finite numbers."""
    diff = abs(a - b)
    allowed = rel * max(abs(a), abs(b)) + floor
    return diff <= allowed, diff, allowed


def _compare(prefix: str, r, rr, scenario, what: str) -> list[Invariant]:
    """Peak contact force, y_max, exit speed and sorted flag of ``r`` against ``rr``."""
    out = []
    mass, g = scenario.parcel.mass, scenario.conveyor.gravity
    ok, diff, allowed = _rel_close(
        r.peak_contact_force, rr.peak_contact_force, CONV_FORCE_REL, CONV_FORCE_ABS_G * mass * g
    )
    out.append(
        Invariant(
            f"{prefix}_peak_force",
            ok,
            diff,
            allowed,
            f"peak N {r.peak_contact_force:.6g} N vs {rr.peak_contact_force:.6g} N {what}",
        )
    )
    if r.sorted and rr.sorted and scenario.solver.stop_when_sorted:
        out.append(
            Invariant(
                f"{prefix}_y_max",
                True,
                "n/a",
                "n/a",
                "stopped at y0 = s: y_max is the last step's overshoot; exit speed compared",
            )
        )
    else:
        ok, diff, allowed = _rel_close(r.y_max, rr.y_max, CONV_Y_REL, CONV_Y_ABS)
        out.append(
            Invariant(
                f"{prefix}_y_max",
                ok,
                diff,
                allowed,
                f"y_max {r.y_max:.6g} m vs {rr.y_max:.6g} m {what}",
            )
        )
    if r.sorted and rr.sorted:
        ok, diff, allowed = _rel_close(
            r.exit_speed_y, rr.exit_speed_y, CONV_EXIT_REL, CONV_EXIT_ABS
        )
        out.append(
            Invariant(
                f"{prefix}_exit_speed",
                ok,
                diff,
                allowed,
                f"exit {r.exit_speed_y:.6g} m/s vs {rr.exit_speed_y:.6g} m/s {what}",
            )
        )
    else:
        out.append(Invariant(f"{prefix}_exit_speed", True, "n/a", "n/a", "not sorted"))
    same = r.sorted == rr.sorted
    out.append(
        Invariant(
            f"{prefix}_sorted",
            same,
            "same" if same else f"{r.sorted} vs {rr.sorted}",
            "same",
            f"sorted {r.sorted} vs {rr.sorted} {what}",
        )
    )
    return out


def _touched(r) -> bool:
    return any(s != Stage.ON_BELT.label for s, _ in r.stages)


def _named_diagnosis(diagnosis: str | None, cause: str = "") -> Invariant:
    text = diagnosis or ""
    named = bool(text.strip()) and any(k in text for k in KNOWN_CAUSES)
    if cause:
        named = named and cause in text
    return Invariant(
        "diagnosis_named",
        named,
        text or "(none)",
        f"names {cause!r}" if cause else "names a known cause",
    )


def _second_solve(name: str, sc2, r, what: str) -> tuple[object | None, list[Invariant]]:
    """Solve ``sc2`` and compare it with ``r``; a failed or crashed solve fails ``name``."""

    try:
        rr = simulate(sc2, SortingModel(sc2))
    except Exception as exc:  # a crash is a bug, not a diagnosis
        return None, [Invariant(f"{name}_solve", False, f"{type(exc).__name__}: {exc}", "solved")]
    if not rr.success:
        return rr, [
            Invariant(
                f"{name}_solve",
                False,
                rr.diagnosis or "(no diagnosis)",
                "solved",
                f"the solve {what} failed",
            )
        ]
    return rr, _compare(name, r, rr, sc2, what)


def run_case(case: Case, convergence: bool = True) -> CaseResult:
    """Load, solve (nominal, halved step, fine reference if any), check the invariants, judge."""
    wall0 = time.perf_counter()
    invs: list[Invariant] = []
    try:
        loaded = load_scene(case.scene, case.override_strings())
        ref_loaded = (
            load_scene(
                case.scene,
                case.override_strings()
                + [f"{k}={yaml_value(v)}" for k, v in case.reference.items()],
            )
            if case.reference
            else None
        )
    except ParameterError as exc:
        return CaseResult(
            case,
            FAIL,
            False,
            [Invariant("scene_valid", False, str(exc), "valid")],
            error=f"scene invalid: {exc}",
            wall_time=time.perf_counter() - wall0,
        )
    sc = loaded.scenario
    warnings = loaded.warnings
    if case.expected == "warning":
        hit = [w for w in warnings if case.warning in w]
        invs.append(
            Invariant(
                "warning",
                bool(hit),
                hit[0] if hit else "(no warning)",
                f"a warning containing {case.warning!r}",
            )
        )
    try:
        model = SortingModel(sc)
        r = simulate(sc, model)
        audit = r.energy
    except Exception as exc:  # a crash is a bug, not a diagnosis
        invs.append(Invariant("no_exception", False, f"{type(exc).__name__}: {exc}", "none"))
        return CaseResult(
            case,
            FAIL,
            False,
            invs,
            warnings=warnings,
            error="".join(traceback.format_exception_only(type(exc), exc)).strip(),
            wall_time=time.perf_counter() - wall0,
        )
    deep = model.deep
    tol = ENERGY_ABS + ENERGY_REL * audit.flow if math.isfinite(audit.flow) else math.nan
    invs.append(
        Invariant(
            "bounded_time",
            r.wall_time <= sc.solver.max_wall_time + TIME_GRACE,
            r.wall_time,
            sc.solver.max_wall_time,
            f"solver.max_wall_time {sc.solver.max_wall_time:g} s (+{TIME_GRACE:g} s grace)",
        )
    )
    refined = None
    refinement = ""
    if not r.success:
        cause = case.cause if case.expected == "diagnosed" else ""
        invs.append(_named_diagnosis(r.diagnosis, cause))
        verdict = DIAGNOSED if all(i.passed for i in invs if i.name != "warning") else FAIL
    else:
        invs.append(_finite_check(r))
        rise = audit.max_rise
        t_a, t_b = audit.t_rise
        invs.append(
            Invariant(
                "energy",
                math.isfinite(rise) and rise <= tol,
                rise,
                tol,
                f"largest rise of E_load - W_sources over [{t_a:.4f}, {t_b:.4f}] s; "
                f"E_flow {audit.flow:.4g} J; observer's energy_excess {r.energy_excess:.3g} J",
            )
        )
        if case.elastic:
            worst = max(abs(audit.max_residual), abs(audit.min_residual))
            invs.append(
                Invariant(
                    "energy_conserved",
                    math.isfinite(worst) and worst <= tol,
                    worst,
                    tol,
                    f"elastic limit: |E_load - E_load(0) - W_sources| both ways "
                    f"(max {audit.max_residual:.3g} J at {audit.t_max:.4f} s, "
                    f"min {audit.min_residual:.3g} J at {audit.t_min:.4f} s)",
                )
            )
        invs.append(
            Invariant(
                "penetration",
                math.isfinite(r.max_penetration) and r.max_penetration <= deep,
                r.max_penetration / deep,
                1.0,
                f"D_max {r.max_penetration:.4g} m, limit {deep:.4g} m",
            )
        )
        if case.stage:
            seen = [s for s, _ in r.stages]
            invs.append(
                Invariant(
                    "stage",
                    case.stage in seen,
                    " ".join(seen),
                    case.stage,
                    f"the event must reach {case.stage}",
                )
            )
        if convergence and case.convergence:
            refinement = refinement_text(sc.solver)
            sc2 = dataclasses.replace(sc, solver=refined_solver(sc.solver))
            refined, more = _second_solve("conv", sc2, r, "at half the step")
            invs.extend(more)
        if ref_loaded is not None:
            what = (
                "against the fine reference ("
                + ", ".join(f"{k}={v}" for k, v in case.reference.items())
                + ")"
            )
            rr, more = _second_solve("ref", ref_loaded.scenario, r, what)
            invs.extend(more)
            if rr is not None and rr.success:
                invs.append(
                    Invariant(
                        "ref_touched",
                        _touched(r) == _touched(rr),
                        f"{_touched(r)} vs {_touched(rr)}",
                        "same",
                        f"the fence touched the load: {_touched(r)} at the case's step, "
                        f"{_touched(rr)} {what}",
                    )
                )
        verdict = PASS if all(i.passed for i in invs) else FAIL
    if case.expected == "pass":
        meets = verdict == PASS
    elif case.expected == "diagnosed":
        meets = verdict == DIAGNOSED
    else:
        warned = invs[0].passed
        meets = warned and verdict in (PASS, DIAGNOSED)
        if not warned:
            verdict = FAIL
    return CaseResult(
        case,
        verdict,
        meets,
        invs,
        warnings=warnings,
        diagnosis=r.diagnosis,
        result=r,
        refined=refined,
        audit=audit,
        energy_tolerance=tol,
        deep_limit=deep,
        refinement=refinement,
        wall_time=time.perf_counter() - wall0,
    )


def warm_up(cases: Sequence[Case]) -> float:
    """Compile the kernel for the methods the cases use (a short solve each); return seconds."""
    wall0 = time.perf_counter()
    methods = {str(c.overrides.get("solver.method", "adaptive")) for c in cases}
    for method in sorted(methods):
        for scene in ("impact_flexible", "positioned_stiff"):
            loaded = load_scene(scene, [f"solver.method={method}", "solver.t_end=0.3"])
            simulate(loaded.scenario, SortingModel(loaded.scenario))
    return time.perf_counter() - wall0


def run_cases(
    cases: Sequence[Case],
    progress: Callable[[CaseResult], None] | None = None,
    convergence: bool = True,
) -> list[CaseResult]:
    out = []
    for case in cases:
        cr = run_case(case, convergence=convergence)
        out.append(cr)
        if progress is not None:
            progress(cr)
    return out
