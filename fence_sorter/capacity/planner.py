"""The controller's stroke planner: (R_s, t1) per load, best capacity W_t (1) first.

Candidates (R_s, t1) from the ranges (3) and (5) are ordered once by W_t (1) (t_z ascending,
then the gentler stroke first); a configured decision table (optima of the sweep
``decision-table``, benchmarks.paper.decision) puts the stroke of the load's class first.
For a load, the candidates its timing admits (the load front must still be upstream of R_s
when the command is out, the fence must be free) are tried in W_t order for half the
evaluation budget, then on an even spread over the rest (feasibility is not monotone along the
order), stopping at the first feasible one: the answer is always an evaluated, feasible
stroke, or a reason naming the violated constraint. Evaluations are cached per quantised load
class.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace

from fence_sorter.capacity.constraints import (
    CONSTRAINT_IDS,
    ConstraintProfile,
    footprint_length,
    margin_working_time,
)
from fence_sorter.capacity.decision_table import DecisionTable
from fence_sorter.capacity.evaluate import StrokeEvaluation, evaluate_stroke, planning_scenario
from fence_sorter.capacity.formulas import scraping_time
from fence_sorter.physics.params import ParameterError, ParcelParams, check_range
from fence_sorter.physics.simulate import Scenario

#: a candidate feasible for fewer than HOPELESS_RATE of the (at least HOPELESS_AFTER) load
#: classes it was tried on is moved behind the others
HOPELESS_AFTER = 3
HOPELESS_RATE = 0.5
#: evaluations per load class during the warm-up (it also learns which candidates never work)
WARMUP_BUDGET = 30


@dataclass(frozen=True)
class PlannerConfig:
    """Planner settings (SI; the config's degrees are converted by :meth:`from_mapping`)."""

    alpha_k: float = math.radians(40.0)
    t1_min: float = 0.2
    t1_max: float = 1.5
    t1_step: float = 0.1
    r_s_min: float = -0.4
    r_s_max: float = 1.0
    r_s_step: float = 0.2
    profile: ConstraintProfile = ConstraintProfile()
    pitch_gap: float = 0.1  # Delta of (2) [m]
    fence_model: str = "stiff"  # "stiff" or "scene"
    max_evaluations: int = 6  # twin evaluations per load (cached ones are free)
    start_margin: float = 0.1  # command out at least this long before the front is at R_s [s]
    busy_margin: float = 0.05  # idle time between two strokes [s]
    quantum_size: float = 0.05  # [m] A, B, cog offsets
    quantum_mass: float = 0.2  # relative mass bin (log steps of 1 + q)
    quantum_gap: float = 0.05  # [m] Delta_s
    quantum_yaw: float = math.radians(5.0)  # [rad]
    quantum_mu: float = 0.05
    min_exit_speed: float = 0.3  # (8) counts only if C_s crosses y0 = s at least this fast [m/s]
    # starting strokes per load class (config/decision_table.yaml, capacity.decision_table);
    # empty: none, the planner works as without it
    decision_table: str = ""

    FLOAT_KEYS = {
        "alpha_k_deg": (1.0, 89.0, "deg"),
        "t1_min": (0.02, 10.0, "s"),
        "t1_max": (0.02, 10.0, "s"),
        "t1_step": (0.001, 10.0, "s"),
        "r_s_min": (-5.0, 5.0, "m"),
        "r_s_max": (-5.0, 5.0, "m"),
        "r_s_step": (0.001, 10.0, "m"),
        "pitch_gap": (0.0, 10.0, "m"),
        "start_margin": (0.0, 10.0, "s"),
        "busy_margin": (0.0, 10.0, "s"),
        "quantum_size": (1e-4, 1.0, "m"),
        "quantum_mass": (1e-3, 10.0, ""),
        "quantum_gap": (1e-4, 1.0, "m"),
        "quantum_yaw_deg": (1e-3, 90.0, "deg"),
        "quantum_mu": (1e-4, 1.0, ""),
        "min_exit_speed": (0.0, 100.0, "m/s"),
        "w_dop": (1e-6, 100.0, "m/s"),
        "a_ndop": (1e-6, 1e5, "m/s^2"),
        "ydot_dop": (1e-6, 100.0, "m/s"),
    }

    def validate(self, prefix: str = "controller") -> PlannerConfig:
        if self.t1_min > self.t1_max:
            raise ParameterError(
                f"{prefix}.t1_min ({self.t1_min:g} s) must not exceed t1_max ({self.t1_max:g} s)"
            )
        if self.r_s_min > self.r_s_max:
            raise ParameterError(
                f"{prefix}.r_s_min ({self.r_s_min:g} m) must not exceed r_s_max "
                f"({self.r_s_max:g} m)"
            )
        if self.fence_model not in ("stiff", "scene"):
            raise ParameterError(
                f"{prefix}.fence_model must be one of stiff, scene, got {self.fence_model!r}"
            )
        check_range(f"{prefix}.max_evaluations", self.max_evaluations, 1, 1000)
        self.profile.validate(prefix)
        return self

    @classmethod
    def from_mapping(cls, data: Mapping, prefix: str = "controller") -> PlannerConfig:
        """From flat config keys (the controller's ROS parameters); unknown keys are ignored
        (the node has other parameters too). Raises ParameterError naming key and range."""
        kw: dict = {}
        for key, (lo, hi, unit) in cls.FLOAT_KEYS.items():
            if key not in data:
                continue
            value = data[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParameterError(f"{prefix}.{key} must be a number, got {value!r}")
            check_range(f"{prefix}.{key}", float(value), lo, hi, unit=unit)
            kw[key] = float(value)
        if "alpha_k_deg" in kw:
            kw["alpha_k"] = math.radians(kw.pop("alpha_k_deg"))
        if "quantum_yaw_deg" in kw:
            kw["quantum_yaw"] = math.radians(kw.pop("quantum_yaw_deg"))
        prof = {k: kw.pop(k) for k in ("w_dop", "a_ndop", "ydot_dop") if k in kw}
        if "active_constraints" in data:
            prof["active"] = list(data["active_constraints"])
        if "fence_model" in data:
            kw["fence_model"] = str(data["fence_model"])
        if "decision_table" in data:
            value = data["decision_table"]
            if not isinstance(value, str):
                raise ParameterError(
                    f"{prefix}.decision_table must be a file path (empty: none), got {value!r}"
                )
            kw["decision_table"] = value
        if "max_evaluations" in data:
            value = data["max_evaluations"]
            if isinstance(value, bool) or not isinstance(value, int):
                raise ParameterError(f"{prefix}.max_evaluations must be an integer, got {value!r}")
            kw["max_evaluations"] = value
        try:
            kw["profile"] = ConstraintProfile.from_mapping(prof, prefix)
        except ParameterError as exc:
            raise ParameterError(
                str(exc).replace(f"{prefix}.active", f"{prefix}.active_constraints")
            ) from None
        return cls(**kw).validate(prefix)

    def candidates(self, v: float) -> list[tuple[float, float]]:
        """(R_s, t1) pairs, best W_t (1) first: t_z ascending, then larger t1, then |R_s|."""
        t1s = _grid(self.t1_min, self.t1_max, self.t1_step)
        rss = _grid(self.r_s_min, self.r_s_max, self.r_s_step)
        pairs = [(r, t) for r in rss for t in t1s]
        pairs.sort(key=lambda p: (round(scraping_time(v, p[1], p[0]), 9), -p[1], abs(p[0])))
        return pairs


def _grid(lo: float, hi: float, step: float) -> list[float]:
    n = int(math.floor((hi - lo) / step + 1e-9))
    return [round(lo + i * step, 9) for i in range(n + 1)]


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
    evaluation: StrokeEvaluation | None
    start_time: float  # when the front reaches R_s (fence start) [s]
    end_time: float  # start + 2 t1 [s]
    reason: str
    evaluations: int = 0  # twin evaluations made for this load
    cache_hits: int = 0
    wall_time: float = 0.0
    admissible: int = 0  # candidates the timing admitted
    tried: list[StrokeEvaluation] = field(default_factory=list)
    refused: int = 0  # feasible strokes the caller's ``accept`` refused (their times)


class Planner:
    """Picks (R_s, t1) per load on the twin; keeps the fence-busy window of its own strokes."""

    def __init__(self, base: Scenario, config: PlannerConfig = PlannerConfig()):
        self.config = config.validate()
        self.base = planning_scenario(base, fence=config.fence_model)
        self.v = base.conveyor.belt_speed
        self.width = base.conveyor.width
        self.candidate_list = config.candidates(self.v)
        self.cache: dict[tuple, StrokeEvaluation] = {}
        self.busy_until = -math.inf
        self.evaluations = 0
        self.cache_hits = 0
        # per candidate: [evaluations, feasible ones] over all load classes so far
        self.record: dict[tuple[float, float], list[int]] = {}
        # per load class: the stroke chosen for it (the hint for its neighbours)
        self.chosen: dict[tuple, tuple[float, float]] = {}
        self.table = None
        if config.decision_table:
            self.table = DecisionTable.load(config.decision_table).check(
                config.alpha_k, self.v, "controller.decision_table"
            )

    # -- load classes ----------------------------------------------------------------------
    def quantise(self, req: LoadRequest) -> tuple[tuple, ParcelParams, float, float]:
        """(class key, representative load, mu1, mu2) of a load (bin centres)."""
        c, p = self.config, req.parcel
        qs = c.quantum_size

        def q(x: float, step: float) -> int:
            return int(round(x / step))

        mass_bin = int(round(math.log(p.mass) / math.log1p(c.quantum_mass)))
        mu1 = req.mu_belt if math.isfinite(req.mu_belt) else self.base.conveyor.mu_belt
        mu2 = req.mu_fence if math.isfinite(req.mu_fence) else self.base.contact.mu_fence
        key = (
            q(p.length_a, qs),
            q(p.width_b, qs),
            mass_bin,
            q(p.cog_offset_x, qs),
            q(p.cog_offset_y, qs),
            q(p.lateral_gap, c.quantum_gap),
            q(p.yaw, c.quantum_yaw),
            q(mu1, c.quantum_mu),
            q(mu2, c.quantum_mu),
        )
        a = max(key[0] * qs, qs)
        b = max(key[1] * qs, qs)
        rep = replace(
            p,
            length_a=a,
            width_b=b,
            mass=math.exp(mass_bin * math.log1p(c.quantum_mass)),
            cog_offset_x=max(-0.5 * a, min(0.5 * a, key[3] * qs)),
            cog_offset_y=max(-0.5 * b, min(0.5 * b, key[4] * qs)),
            yaw=key[6] * c.quantum_yaw,
        )
        room = max(self.width - rep.footprint_width(), 0.0)
        rep = replace(rep, lateral_gap=max(0.0, min(room, key[5] * c.quantum_gap)))
        return key, rep, key[7] * c.quantum_mu, key[8] * c.quantum_mu

    # -- planning --------------------------------------------------------------------------
    def evaluate(self, key: tuple, rep: ParcelParams, mu1: float, mu2: float, cand) -> tuple:
        """(StrokeEvaluation, cached?) of one candidate for a load class."""
        full = (key, cand)
        hit = self.cache.get(full)
        if hit is not None:
            self.cache_hits += 1
            return hit, True
        r_s, t1 = cand
        ev = evaluate_stroke(
            self.base,
            rep,
            r_s,
            t1,
            self.config.alpha_k,
            self.config.profile,
            gap=self.config.pitch_gap,
            mu_belt=mu1,
            mu_fence=mu2,
        )
        self.evaluations += 1
        ev = self._robust(ev)
        self.cache[full] = ev
        rec = self.record.setdefault(cand, [0, 0])
        rec[0] += 1
        rec[1] += int(ev.feasible)
        return ev, False

    def _robust(self, ev: StrokeEvaluation) -> StrokeEvaluation:
        """(8) with a reserve: a load that crawls over y0 = s slower than min_exit_speed would
        miss the chute on a slightly softer fence (the line's flexible one), so it fails (8)."""
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
        """A candidate that failed for most load classes it was tried on (at least
        HOPELESS_AFTER of them): tried after the others."""
        n, ok = self.record.get(cand, (0, 0))
        return n >= HOPELESS_AFTER and ok < HOPELESS_RATE * n

    def admissible(self, req: LoadRequest, now: float) -> list[tuple[float, float]]:
        """Candidates the load's timing and the fence-busy window admit, best W_t first.

        (7) is analytic and filters here too when active: no simulation for a stroke it
        already rules out.
        """
        c = self.config
        out = []
        extent = footprint_length(req.parcel)
        earliest = max(now + c.start_margin, self.busy_until + c.busy_margin)
        for r_s, t1 in self.candidate_list:
            start = req.scan_time + (r_s - req.scan_position_x) / self.v
            if start < earliest:
                continue
            if 7 in c.profile.active and margin_working_time(extent, r_s, self.v, t1) > 0.0:
                continue
            out.append((r_s, t1))
        return out

    def _admits(self, req: LoadRequest, now: float, cand: tuple[float, float]) -> bool:
        """The timing and (7) test of :meth:`admissible` for one candidate."""
        c = self.config
        r_s, t1 = cand
        earliest = max(now + c.start_margin, self.busy_until + c.busy_margin)
        if req.scan_time + (r_s - req.scan_position_x) / self.v < earliest:
            return False
        extent = footprint_length(req.parcel)
        return not (7 in c.profile.active and margin_working_time(extent, r_s, self.v, t1) > 0.0)

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

    def plan(
        self,
        req: LoadRequest,
        now: float,
        *,
        commit: bool = True,
        budget: int | None = None,
        use_hint: bool = True,
        accept: Callable[[StrokeEvaluation, float, float], bool] | None = None,
    ) -> Plan:
        """Plan one load at sim time ``now``; with ``commit`` a feasible stroke books the fence.

        ``accept(evaluation, start, end)``: the caller's own test of a feasible stroke and its
        times (a line's swept-sector guard: another parcel in the sector then; a stroke that
        missed this parcel before); a refused stroke is passed over for the next feasible
        one, and counted in ``Plan.refused``.

        Order: with a decision table, its stroke for the load's class first (unless the class
        has a chosen stroke already); the stroke chosen for the nearest load class
        (``use_hint``; similar loads need similar strokes, so this is mostly the only
        evaluation), then W_t order with the
        candidates that failed for most load classes seen so far behind the others
        (:meth:`hopeless`); the warm-up (no hint, a larger budget) teaches the planner both.
        """
        wall0 = time.perf_counter()
        key, rep, mu1, mu2 = self.quantise(req)
        cands = self.admissible(req, now)
        cands = [c for c in cands if not self.hopeless(c)] + [c for c in cands if self.hopeless(c)]
        hint = self.hint(key) if use_hint else None
        if hint is not None and hint in cands:
            cands.remove(hint)
            cands.insert(0, hint)
        # the decision table's stroke first, unless this very class has a stroke of its own
        first = self.table_candidate(req, now) if key not in self.chosen else None
        if first is not None:
            if first in cands:
                cands.remove(first)
            cands.insert(0, first)
        plan = Plan(req.parcel_id, False, None, math.nan, math.nan, "", admissible=len(cands))
        if not cands:
            plan.reason = self._no_candidate_reason(req, now)
            plan.wall_time = time.perf_counter() - wall0
            return plan
        budget = self.config.max_evaluations if budget is None else budget
        results: dict[int, StrokeEvaluation] = {}

        def times(ev: StrokeEvaluation) -> tuple[float, float]:
            start = req.scan_time + (ev.r_s - req.scan_position_x) / self.v
            return start, start + 2.0 * ev.t1

        first: list[StrokeEvaluation] = []

        def taken(ev: StrokeEvaluation | None) -> bool:
            if ev is None or not ev.feasible:
                return False
            if not first:  # the class's stroke is the first feasible one, by physics alone
                first.append(ev)
                self.chosen[key] = (ev.r_s, ev.t1)
            if accept is not None and not accept(ev, *times(ev)):
                plan.refused += 1
                return False
            return True

        def probe(i: int) -> StrokeEvaluation | None:
            if i in results:
                return results[i]
            if plan.evaluations >= budget:
                return None
            ev, cached = self.evaluate(key, rep, mu1, mu2, cands[i])
            if cached:
                plan.cache_hits += 1
            else:
                plan.evaluations += 1
            results[i] = ev
            plan.tried.append(ev)
            return ev

        # first in W_t order while half the budget lasts, then an even spread over the rest
        # (feasibility is not monotone along the order: some R_s fail (8) for every t1)
        hi = None
        linear = max(1, budget // 2)
        for i in range(min(linear, len(cands))):
            ev = probe(i)
            if taken(ev):
                hi = i
                break
        if hi is None and len(cands) > linear:
            left = budget - plan.evaluations
            rest = range(linear, len(cands))
            n = max(1, left)
            picks = sorted(
                {rest[int(round(k * (len(rest) - 1) / max(n - 1, 1)))] for k in range(n)}
            )
            for i in picks:
                ev = probe(i)
                if ev is None:
                    break
                if taken(ev):
                    hi = i
                    break
        if hi is not None:
            best = results[hi]
            plan.feasible = True
            plan.evaluation = best
            plan.start_time, plan.end_time = times(best)
            plan.reason = ""
            if commit:
                self.busy_until = plan.end_time
        elif plan.refused:
            plan.reason = f"each of the {plan.refused} feasible strokes found was refused"
        else:
            plan.reason = self._infeasible_reason(plan, len(cands))
        plan.wall_time = time.perf_counter() - wall0
        return plan

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

    def _infeasible_reason(self, plan: Plan, n: int) -> str:
        if not plan.tried:
            return "evaluation budget exhausted before any candidate"
        best = min(plan.tried, key=lambda ev: len(ev.violated))
        tail = (
            "budget of evaluations exhausted"
            if plan.evaluations >= self.config.max_evaluations
            else "none feasible"
        )
        return (
            f"no feasible stroke ({len(plan.tried)} of {n} candidates evaluated, {tail}); "
            f"R_s = {best.r_s:g} m, t1 = {best.t1:g} s: {best.diagnosis}"
        )

    # -- warm-up ---------------------------------------------------------------------------
    def warm_up(self, loads: Iterable[ParcelParams], time_budget: float = 10.0) -> int:
        """Fill the cache for the classes of ``loads`` (timing ignored); return classes done.

        The first call compiles/loads the JIT kernel; run this before subscribing."""
        wall0 = time.perf_counter()
        busy = self.busy_until
        done: set[tuple] = set()
        for p in loads:
            if time.perf_counter() - wall0 > time_budget:
                break
            req = LoadRequest(0, p, scan_time=1e6, scan_position_x=-1e6)
            key = self.quantise(req)[0]
            if key in done:
                continue
            done.add(key)
            self.busy_until = -math.inf
            self.plan(req, now=-math.inf, commit=False, budget=WARMUP_BUDGET, use_hint=False)
        self.busy_until = busy
        return len(done)


__all__ = ["CONSTRAINT_IDS", "LoadRequest", "Plan", "Planner", "PlannerConfig"]
