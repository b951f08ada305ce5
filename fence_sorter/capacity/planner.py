"""The controller's stroke planner: (R_s, t1) per load, best capacity W_t (1) first.

Candidates (R_s, t1) from the ranges (3) and (5) are ordered once by W_t (1) (t_z ascending,
then the gentler stroke first). For a load, the candidates its timing admits (the load front
must still be upstream of R_s when the command is out, the fence must be free) are tried: the
stroke chosen for its load class (or the nearest class, or the decision table's) first, then
W_t order, until one is feasible, the command's deadline comes or the safety cap of
evaluations is reached.

Every candidate is evaluated on the plant's model (the scene's fence, flexible where the
scene's is) with the exact load (its own A, B, mass, C_s offsets, gap, yaw, mu1, mu2), and is
feasible only if (7)-(12) hold at the nominal load and at the corners of its uncertainty set
(:mod:`fence_sorter.capacity.uncertainty`). The answer is a verified stroke, or a decline
with its code: NO_FEASIBLE_COMMAND (every admissible candidate evaluated, none feasible; the
reason names the violated constraint) or NO_STROKE_IN_BUDGET (deadline or cap reached with
candidates left). What was learnt per quantised load class (the chosen stroke, the
candidates that failed) only orders the candidates.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace

from fence_sorter.capacity.constraints import (
    CONSTRAINT_IDS,
    footprint_length,
    margin_working_time,
)
from fence_sorter.capacity.decision_table import DecisionTable
from fence_sorter.capacity.evaluate import StrokeEvaluation, evaluate_stroke, planning_scenario
from fence_sorter.capacity.planner_config import PlannerConfig
from fence_sorter.codes import BUDGET_REASON, OutcomeCode
from fence_sorter.physics.params import ParcelParams
from fence_sorter.physics.simulate import Scenario

#: a candidate feasible for fewer than HOPELESS_RATE of the (at least HOPELESS_AFTER) load
#: classes it was tried on is moved behind the others
HOPELESS_AFTER = 3
HOPELESS_RATE = 0.5
#: evaluations per load class during the warm-up (it also learns which candidates never work)
WARMUP_BUDGET = 12
#: exact-load verdicts kept (a re-plan of the same parcel, or the same parcel again)
CACHE_SIZE = 20000


@dataclass(frozen=True)
class LoadRequest:
    """A load to plan for, with its timing (sim time [s])."""

    parcel_id: int
    parcel: ParcelParams
    scan_time: float  # when the front was at scan_position_x
    scan_position_x: float
    mu_belt: float = math.nan  # NaN: the scene's value
    mu_fence: float = math.nan


@dataclass
class Plan:
    """The planner's answer for one load."""

    parcel_id: int
    feasible: bool
    evaluation: StrokeEvaluation | None  # at the nominal load
    start_time: float  # when the front reaches R_s (fence start) [s]
    end_time: float  # start + 2 t1 [s]
    reason: str
    evaluations: int = 0  # twin evaluations made for this load (corners included)
    cache_hits: int = 0
    wall_time: float = 0.0
    admissible: int = 0  # candidates the timing admitted
    tried: list[StrokeEvaluation] = field(default_factory=list)
    refused: int = 0  # feasible strokes the caller's ``accept`` refused (their times)
    #: why there is no stroke: NO_STROKE_IN_BUDGET (deadline or cap reached with candidates
    #: left) or NO_FEASIBLE_COMMAND; None when feasible
    code: OutcomeCode | None = None
    violated: tuple[int, ...] = ()  # the constraints the best candidate tried failed

    @property
    def budget_ran_out(self) -> bool:
        return self.code is OutcomeCode.NO_STROKE_IN_BUDGET


def _load_key(p: ParcelParams, mu1: float, mu2: float) -> tuple:
    return (
        p.length_a, p.width_b, p.height, p.mass, p.cog_offset_x, p.cog_offset_y,
        p.lateral_gap, p.yaw, mu1, mu2,
    )  # fmt: skip


class Planner:
    """Picks (R_s, t1) per load on the twin; keeps the fence-busy window of its own strokes."""

    def __init__(self, base: Scenario, config: PlannerConfig | None = None):
        config = PlannerConfig() if config is None else config
        self.config = config.validate()
        self.base = planning_scenario(base, fence=config.fence_model)
        self.v = base.conveyor.belt_speed
        self.width = base.conveyor.width
        self.candidate_list = config.candidates(self.v)
        self.corners = config.uncertainty.corners()
        # exact load and candidate -> its verdict over the uncertainty set
        self.cache: dict[tuple, StrokeEvaluation] = {}
        self.busy_until = -math.inf
        self.evaluations = 0
        self.cache_hits = 0
        # per candidate: [verdicts, feasible ones] over all loads so far
        self.record: dict[tuple[float, float], list[int]] = {}
        # per load class: the stroke chosen for it (the hint for its neighbours)
        self.chosen: dict[tuple, tuple[float, float]] = {}
        # (load class, candidate) -> the verdict of the last load of that class
        self.class_verdict: dict[tuple, bool] = {}
        # corner name -> strokes it failed (the likeliest to fail is checked first)
        self.corner_failures: dict[str, int] = {c.name: 0 for c in self.corners}
        self.table = None
        if config.decision_table:
            self.table = DecisionTable.load(config.decision_table).check(
                config.alpha_k, self.v, "controller.decision_table"
            )

    # -- load classes ----------------------------------------------------------------------
    def mus(self, req: LoadRequest) -> tuple[float, float]:
        """The load's mu1 and mu2 (the scene's where the request has none)."""
        mu1 = req.mu_belt if math.isfinite(req.mu_belt) else self.base.conveyor.mu_belt
        mu2 = req.mu_fence if math.isfinite(req.mu_fence) else self.base.contact.mu_fence
        return mu1, mu2

    def class_key(self, req: LoadRequest) -> tuple:
        """The quantised load class of a load (bins of the config's quanta)."""
        c, p = self.config, req.parcel
        qs = c.quantum_size
        mu1, mu2 = self.mus(req)

        def q(x: float, step: float) -> int:
            return int(round(x / step))

        return (
            q(p.length_a, qs),
            q(p.width_b, qs),
            int(round(math.log(p.mass) / math.log1p(c.quantum_mass))),
            q(p.cog_offset_x, qs),
            q(p.cog_offset_y, qs),
            q(p.lateral_gap, c.quantum_gap),
            q(p.yaw, c.quantum_yaw),
            q(mu1, c.quantum_mu),
            q(mu2, c.quantum_mu),
        )

    # -- evaluation ------------------------------------------------------------------------
    def _evaluate(self, p: ParcelParams, mu1: float, mu2: float, cand) -> StrokeEvaluation:
        r_s, t1 = cand
        ev = evaluate_stroke(
            self.base,
            p,
            r_s,
            t1,
            self.config.alpha_k,
            self.config.profile,
            gap=self.config.pitch_gap,
            mu_belt=mu1,
            mu_fence=mu2,
        )
        self.evaluations += 1
        return self._robust(ev)

    def verify(
        self,
        p: ParcelParams,
        mu1: float,
        mu2: float,
        cand: tuple[float, float],
        out_of_time: Callable[[], bool] = lambda: False,
        corners: bool = True,
    ) -> tuple[StrokeEvaluation | None, bool]:
        """(verdict, cached?) of one candidate for the exact load over its uncertainty set.

        The nominal load first, then the corners, the one that failed most often first; the
        first failure ends it. The verdict carries the nominal figures; infeasible at a
        corner, it names the corner and the violated constraint; feasible, ``extra['worst']``
        holds the largest w_n, a_N and exit speed over the corners. None: ``out_of_time``
        said so before the last corner (nothing is cached then). Without ``corners`` only the
        nominal load is simulated (the warm-up's learning; not cached, it is no verdict)."""
        if not corners:
            return self._evaluate(p, mu1, mu2, cand), False
        key = (_load_key(p, mu1, mu2), cand)
        hit = self.cache.get(key)
        if hit is not None:
            self.cache_hits += 1
            return hit, True
        nominal = self._evaluate(p, mu1, mu2, cand)
        verdict = nominal
        if nominal.feasible:
            worst = {
                "impact_speed": nominal.impact_speed,
                "peak_accel": nominal.peak_accel,
                "exit_speed": nominal.exit_speed,
            }
            order = sorted(self.corners, key=lambda c: -self.corner_failures[c.name])
            for corner in order:
                if out_of_time():
                    return None, False
                q, m1, m2 = self.config.uncertainty.apply(corner, p, mu1, mu2, self.width)
                ev = self._evaluate(q, m1, m2, cand)
                if not ev.feasible:
                    self.corner_failures[corner.name] += 1
                    verdict = replace(
                        nominal,
                        feasible=False,
                        violated=ev.violated,
                        diagnosis=f"at the {corner.name} corner of the uncertainty set: "
                        + ev.diagnosis,
                        extra={"corner": corner.name, "at_corner": ev},
                    )
                    break
                for k in worst:
                    worst[k] = max(worst[k], getattr(ev, k))
            else:
                verdict = replace(nominal, extra={"worst": worst})
        if len(self.cache) >= CACHE_SIZE:
            self.cache.clear()
        self.cache[key] = verdict
        return verdict, False

    def _robust(self, ev: StrokeEvaluation) -> StrokeEvaluation:
        """(8) with a reserve: a load that crawls over y0 = s slower than min_exit_speed would
        miss the chute on a slightly different load or fence, so it fails (8)."""
        c = self.config
        if not (ev.feasible and 8 in c.profile.active and ev.exit_speed < c.min_exit_speed):
            return ev
        return replace(
            ev,
            feasible=False,
            violated=(8,),
            diagnosis=(
                f"(8) push-off marginal: C_s crosses y0 = s at {ev.exit_speed:.3g} m/s "
                f"< min_exit_speed {c.min_exit_speed:g} m/s"
            ),
        )

    def hopeless(self, cand: tuple[float, float]) -> bool:
        """A candidate that failed for most loads it was tried on (at least HOPELESS_AFTER of
        them): tried after the others."""
        n, ok = self.record.get(cand, (0, 0))
        return n >= HOPELESS_AFTER and ok < HOPELESS_RATE * n

    # -- timing ----------------------------------------------------------------------------
    def start_of(self, req: LoadRequest, cand: tuple[float, float]) -> float:
        """When the load's front reaches the candidate's R_s [s]."""
        return req.scan_time + (cand[0] - req.scan_position_x) / self.v

    def admissible(self, req: LoadRequest, now: float) -> list[tuple[float, float]]:
        """Candidates the load's timing and the fence-busy window admit, best W_t first.

        (7) is analytic and filters here too when active: no simulation for a stroke it
        already rules out.
        """
        return [cand for cand in self.candidate_list if self._admits(req, now, cand)]

    def _admits(self, req: LoadRequest, now: float, cand: tuple[float, float]) -> bool:
        """The timing and (7) test of :meth:`admissible` for one candidate."""
        c = self.config
        r_s, t1 = cand
        earliest = max(now + c.start_margin, self.busy_until + c.busy_margin)
        if self.start_of(req, cand) < earliest:
            return False
        extent = footprint_length(req.parcel)
        return not (7 in c.profile.active and margin_working_time(extent, r_s, self.v, t1) > 0.0)

    def deadline(self, req: LoadRequest, now: float, rtf: float, wall_now: float) -> float:
        """The latest wall time (``time.perf_counter``) for the load's command to be out:
        the front reaches the largest R_s less ``start_margin`` then, at ``rtf`` sim seconds
        per wall second, less ``deadline_margin``; ``min_planning_time`` after ``wall_now``
        at the least."""
        c = self.config
        last = max(r for r, _ in self.candidate_list)
        left = self.start_of(req, (last, 0.0)) - c.start_margin - now
        return wall_now + max(left / max(rtf, 1e-9) - c.deadline_margin, c.min_planning_time)

    def table_candidate(self, req: LoadRequest, now: float) -> tuple[float, float] | None:
        """The decision table's stroke for the load's class, if a table is configured and
        the load's timing admits it (the planner then tries it first)."""
        if self.table is None:
            return None
        p = req.parcel
        cand = self.table.lookup(footprint_length(p), p.lateral_gap, p.yaw)
        return cand if cand is not None and self._admits(req, now, cand) else None

    def hint(self, key: tuple) -> tuple[float, float] | None:
        """The stroke chosen for the nearest load class planned so far (L1 over the bins)."""
        if key in self.chosen:
            return self.chosen[key]
        best, dist = None, math.inf
        for other, cand in self.chosen.items():
            d = sum(abs(a - b) for a, b in zip(key, other, strict=True))
            if d < dist:
                best, dist = cand, d
        return best

    # -- planning --------------------------------------------------------------------------
    def order(self, req: LoadRequest, now: float, key: tuple, use_hint: bool) -> list:
        """The admissible candidates in the order they are tried: the decision table's
        stroke (unless the class has a chosen one), the class's (or nearest class's) chosen
        stroke, then W_t order, the candidates that failed for this class or for most loads
        behind the others. With a deadline rather than a count as the budget, plain W_t order
        finds the best capacity the time allows."""
        cands = self.admissible(req, now)
        bad = {c for c in cands if self.hopeless(c) or self.class_verdict.get((key, c)) is False}
        ordered = [c for c in cands if c not in bad] + [c for c in cands if c in bad]
        hint = self.hint(key) if use_hint else None
        if hint is not None and hint in ordered:
            ordered.remove(hint)
            ordered.insert(0, hint)
        # the table's stroke (admitted, on the grid or not) first of all
        first = self.table_candidate(req, now) if key not in self.chosen else None
        if first is not None:
            if first in ordered:
                ordered.remove(first)
            ordered.insert(0, first)
        return ordered

    def plan(
        self,
        req: LoadRequest,
        now: float,
        *,
        commit: bool = True,
        budget: int | None = None,
        deadline: float | None = None,
        rtf: float | None = None,
        use_hint: bool = True,
        accept: Callable[[StrokeEvaluation, float, float], bool] | None = None,
        corners: bool = True,
    ) -> Plan:
        """Plan one load at sim time ``now``; with ``commit`` a feasible stroke books the fence.

        Candidates are verified (:meth:`verify`) in :meth:`order` until one is feasible,
        the wall time ``deadline`` (``time.perf_counter``; None: none) comes or ``budget``
        twin evaluations (default ``max_evaluations``, a safety cap) are spent. With ``rtf``
        (sim seconds per wall second) a candidate whose start has come too close while
        planning is passed over.

        ``accept(evaluation, start, end)``: the caller's own test of a feasible stroke and its
        times (a line's swept-sector guard: another parcel in the sector then; a stroke that
        missed this parcel before); a refused stroke is passed over for the next feasible
        one, and counted in ``Plan.refused``. ``corners=False``: the nominal load only (the
        warm-up's; such a plan is no verdict over the uncertainty set).
        """
        wall0 = time.perf_counter()
        evals0 = self.evaluations
        key = self.class_key(req)
        mu1, mu2 = self.mus(req)
        cands = self.order(req, now, key, use_hint)
        plan = Plan(req.parcel_id, False, None, math.nan, math.nan, "", admissible=len(cands))
        plan.code = OutcomeCode.NO_FEASIBLE_COMMAND
        if not cands:
            plan.reason = self._no_candidate_reason(req, now)
            plan.wall_time = time.perf_counter() - wall0
            return plan
        cap = self.config.max_evaluations if budget is None else budget
        margin = self.config.start_margin

        def spent() -> int:
            return self.evaluations - evals0

        def out_of_time() -> bool:
            return spent() >= cap or (deadline is not None and time.perf_counter() >= deadline)

        chosen = None
        left = len(cands)
        for cand in cands:
            if out_of_time():
                break
            left -= 1
            if rtf is not None:
                sim_now = now + rtf * (time.perf_counter() - wall0)
                if self.start_of(req, cand) < sim_now + margin:
                    left += 1  # too late by now: not evaluated, it counts as left
                    continue
            ev, cached = self.verify(req.parcel, mu1, mu2, cand, out_of_time, corners)
            if ev is None:
                left += 1
                break
            plan.cache_hits += int(cached)
            plan.tried.append(ev)
            if not cached:
                rec = self.record.setdefault(cand, [0, 0])
                rec[0] += 1
                rec[1] += int(ev.feasible)
            self.class_verdict[(key, cand)] = ev.feasible
            if not ev.feasible:
                continue
            if not any(e.feasible for e in plan.tried[:-1]):
                self.chosen[key] = cand  # the class's stroke: the first feasible, by physics
            start = self.start_of(req, cand)
            if accept is not None and not accept(ev, start, start + 2.0 * ev.t1):
                plan.refused += 1
                continue
            chosen = ev
            break
        plan.evaluations = spent()
        if chosen is not None:
            plan.feasible = True
            plan.code = None
            plan.evaluation = chosen
            plan.start_time = self.start_of(req, (chosen.r_s, chosen.t1))
            plan.end_time = plan.start_time + 2.0 * chosen.t1
            if commit:
                self.busy_until = plan.end_time
        elif left > 0:
            plan.code = OutcomeCode.NO_STROKE_IN_BUDGET
            plan.reason = self._budget_reason(plan, len(cands), cap, deadline)
        elif plan.refused:
            plan.reason = f"each of the {plan.refused} feasible strokes found was refused"
        else:
            plan.reason = self._infeasible_reason(plan, len(cands))
        if plan.tried and not plan.feasible:
            plan.violated = self._best_tried(plan).violated
        plan.wall_time = time.perf_counter() - wall0
        return plan

    @staticmethod
    def _best_tried(plan: Plan) -> StrokeEvaluation:
        return min(plan.tried, key=lambda ev: len(ev.violated))

    def _no_candidate_reason(self, req: LoadRequest, now: float) -> str:
        c = self.config
        last = max(r for r, _ in self.candidate_list)
        t_last = req.scan_time + (last - req.scan_position_x) / self.v
        if t_last < now + c.start_margin:
            return (
                f"too late: the front passes R_s = {last:g} m at t = {t_last:.3f} s, "
                f"before the command can be out (now {now:.3f} s + {c.start_margin:g} s)"
            )
        if t_last < self.busy_until + c.busy_margin:
            return (
                f"fence busy until t = {self.busy_until:.3f} s, after the load's last "
                f"admissible start ({t_last:.3f} s)"
            )
        return "(7) working time: no (R_s, t1) in the ranges lets the load into the working space"

    def _budget_reason(self, plan: Plan, n: int, cap: int, deadline: float | None) -> str:
        by = (
            f"the cap of {cap} evaluations"
            if plan.evaluations >= cap or deadline is None
            else "the command's deadline"
        )
        text = (
            f"{BUDGET_REASON}: {len(plan.tried)} of {n} candidates verified by {by} "
            f"({plan.evaluations} evaluations)"
        )
        if plan.tried:
            best = self._best_tried(plan)
            text += f"; R_s = {best.r_s:g} m, t1 = {best.t1:g} s: {best.diagnosis}"
        return text

    def _infeasible_reason(self, plan: Plan, n: int) -> str:
        best = self._best_tried(plan)
        return (
            f"no feasible stroke (all {n} admissible candidates evaluated over the uncertainty "
            f"set); R_s = {best.r_s:g} m, t1 = {best.t1:g} s: {best.diagnosis}"
        )

    # -- warm-up ---------------------------------------------------------------------------
    def warm_up(self, loads: Iterable[ParcelParams], time_budget: float = 10.0) -> int:
        """Plan ``loads`` at their nominal figures (timing ignored, up to WARMUP_BUDGET
        evaluations each, one per load class) to learn the classes' strokes and the
        candidates that fail; return classes done. Nothing is cached as a verdict: each
        parcel's stroke is verified over its uncertainty set when it is planned. The first
        call compiles/loads the JIT kernel; run this before subscribing."""
        wall0 = time.perf_counter()
        busy = self.busy_until
        done: set[tuple] = set()
        for p in loads:
            if time.perf_counter() - wall0 > time_budget:
                break
            req = LoadRequest(0, p, scan_time=1e6, scan_position_x=-1e6)
            key = self.class_key(req)
            if key in done:
                continue
            done.add(key)
            self.busy_until = -math.inf
            self.plan(
                req,
                now=-math.inf,
                commit=False,
                budget=WARMUP_BUDGET,
                deadline=wall0 + time_budget,
                corners=False,
            )
        self.busy_until = busy
        return len(done)


__all__ = ["BUDGET_REASON", "CONSTRAINT_IDS", "LoadRequest", "Plan", "Planner", "PlannerConfig"]
