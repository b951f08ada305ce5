"""What one sorting event produced: :class:`SimulationResult`, and the :class:`Observer` that
reduces a run's accepted points to it (peaks, impact speed, N_stiff, stages, and an energy audit:
the load's energy never rises above the work its power sources did on it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import kernel as K
from .contacts import STAGE_SORTED, classify
from .model import SortingModel


@dataclass
class EnergyAudit:
    """The balance r(t) = E_load(t) - E_load(0) - W_sources(t), both ways, and E_flow.

    E_load is kinetic energy plus sum k_p D^5 / 5; W_sources the work of the fence surface
    velocity on the contact forces, of the belt velocity on the belt friction, and of the
    external wrench (trapezoidal quadrature over the accepted points). Energy never rises
    without a source: r never grows over any interval ([t1, t2], ``max_rise``); in the elastic
    limit it stays ~0 both ways. E_flow = E_load(0) + integral |P_sources| dt scales the
    quadrature's tolerance.
    """

    max_residual: float = 0.0  # max r (the result's energy_excess) [J]
    min_residual: float = 0.0  # min r: energy dissipated [J]
    flow: float = math.nan  # E_flow [J]
    e0: float = math.nan
    t_max: float = 0.0  # when max_residual happened [s]
    t_min: float = 0.0
    max_rise: float = 0.0  # largest rise of r over any interval [t1, t2] [J]
    t_rise: tuple[float, float] = (0.0, 0.0)  # that interval [s]
    run_min: float = 0.0
    t_run_min: float = 0.0

    def update(self, t: float, r: float) -> None:
        if not math.isfinite(r):
            self.max_residual = self.min_residual = r
            return
        if not math.isfinite(self.max_residual):
            return
        if r > self.max_residual:
            self.max_residual, self.t_max = r, t
        if r < self.min_residual:
            self.min_residual, self.t_min = r, t
        if r < self.run_min:
            self.run_min, self.t_run_min = r, t
        if r - self.run_min > self.max_rise:
            self.max_rise, self.t_rise = r - self.run_min, (self.t_run_min, t)


@dataclass
class SimulationResult:
    """Outcome of one event; ``series`` holds only the time series the scenario asked for."""

    success: bool
    sorted: bool
    reason: str
    diagnosis: str | None
    peak_contact_force: float  # max of N summed over fence contacts [N]
    peak_contact_force_stiff: float  # max N_stiff over the impacts [N]
    peak_normal_accel: float  # a_N = N / m_p at its peak [m/s^2]
    impact_normal_speed: float  # w_n at the first contact onset [m/s]
    exit_speed_y: float  # ydot when C_s crosses y0 = s [m/s] (nan if not sorted)
    y_max: float  # y_k: largest C_s ordinate reached [m]
    peak_tip_deflection: float  # [m]
    stages: list[tuple[str, float]]
    sim_time: float
    wall_time: float
    steps: int
    rejected_steps: int
    forced_steps: int = 0  # steps taken unconverged across a model discontinuity
    method: str = ""
    events: int = 0  # contact onsets / releases located
    energy_excess: float = 0.0  # max over t of E_load(t) - E_load(0) - W_sources(t) [J]
    energy: EnergyAudit = field(default_factory=EnergyAudit)  # the whole balance
    max_penetration: float = 0.0  # deepest D of any contact [m]
    # (onset time [s], w_n [m/s], peak N_stiff [N]) per impact
    impacts: list[tuple[float, float, float]] = field(default_factory=list)
    series: dict[str, np.ndarray] = field(default_factory=dict)
    model_parts: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """The JSON outcome of ``fence-sorter simulate --json``."""

        def num(v):
            return None if v is None or not math.isfinite(v) else float(v)

        return {
            "success": self.success,
            "sorted": self.sorted,
            "reason": self.reason,
            "diagnosis": self.diagnosis,
            "peak_contact_force_N": num(self.peak_contact_force),
            "peak_contact_force_stiff_N": num(self.peak_contact_force_stiff),
            "peak_normal_accel_mps2": num(self.peak_normal_accel),
            "impact_normal_speed_mps": num(self.impact_normal_speed),
            "exit_speed_y_mps": num(self.exit_speed_y),
            "y_max_m": num(self.y_max),
            "peak_tip_deflection_m": num(self.peak_tip_deflection),
            "stages": [{"stage": s, "start_s": round(t, 9)} for s, t in self.stages],
            "sim_time_s": self.sim_time,
            "wall_time_s": self.wall_time,
            "steps": self.steps,
            "rejected_steps": self.rejected_steps,
            "forced_steps": self.forced_steps,
            "method": self.method,
            "events": self.events,
            "energy_excess_J": num(self.energy_excess),
            "max_penetration_m": num(self.max_penetration),
            "model_parts": list(self.model_parts),
        }


class Observer:
    """Reduces the accepted points of a run to a :class:`SimulationResult` (any method).

    Sorting: C_s crossing y0 = s (interpolated); impacts: a fence contact starting after none,
    with N_stiff from the rigid-wall solve at its w_n; stages E1-E4 from the contact set; the
    energy audit: E_load = kinetic + sum k D^5 / 5 must stay below E_load(0) plus the work of the
    power sources (fence surface velocity times contact force, belt velocity times belt friction)
    and the external wrench.
    """

    def __init__(self, model: SortingModel):
        self.md = model
        sc = model.sc
        self.width = sc.conveyor.width
        self.stop_when_sorted = sc.solver.stop_when_sorted
        self.want = set(sc.record)
        self.rec: dict[str, list] = {}
        self.sorted = False
        self.touched = False
        self.had_fence = False
        self.exit_speed = math.nan
        self.impact_speed = math.nan
        self.impacts: list[tuple[float, float, float]] = []
        self.peak_n = 0.0
        self.peak_tip = 0.0
        self.max_depth = 0.0
        self.y_max = -math.inf
        self.stage = None
        self.stages: list[tuple[str, float]] = []
        self.prev_t = 0.0
        self.prev_y = np.zeros(6)
        self.prev_power = 0.0
        self.work = 0.0
        self.last_n = [0.0, 0.0, 0.0]
        self.last_t = [0.0, 0.0, 0.0]
        self.last_mask = [-1, -1]  # contact masks at the two points before this one
        self.first = True
        self.audit = EnergyAudit()
        self.mask = -1

    def __call__(self, st, on_belt: bool) -> tuple[bool, bool]:
        md, y, res = self.md, st.y, st.res
        t = st.t
        vx, vy, om = y[3], y[4], y[5]
        energy = 0.5 * md.mass * (vx * vx + vy * vy) + 0.5 * md.inertia * om * om
        energy += res[K.R_ENERGY_CONTACT]
        ext = md.sc.external_wrench
        power = res[K.R_POWER_FENCE] + ext[0] * vx + ext[1] * vy + ext[2] * om
        if on_belt:
            power += st.lam[0] * md.belt
        audit = self.audit
        if self.first:
            self.first = False
            audit.e0 = energy
            audit.flow = abs(energy)
            self.y_max = y[1]
        else:
            h = t - self.prev_t
            self.work += 0.5 * h * (power + self.prev_power)
            audit.flow += 0.5 * h * (abs(power) + abs(self.prev_power))
            audit.update(t, energy - audit.e0 - self.work)
            if y[1] >= self.width > self.prev_y[1] and not self.sorted:
                frac = (self.width - self.prev_y[1]) / (y[1] - self.prev_y[1])
                self.exit_speed = self.prev_y[4] + frac * (vy - self.prev_y[4])
                self.sorted = True
        mask = int(res[K.R_ACTIVE_MASK])
        fence_on = (mask & 0xFF) != 0
        if fence_on and not self.had_fence:
            self.touched = True
            slots = np.flatnonzero(st.out[: K.SLOT_BORDER, K.C_ACTIVE])
            w_n = float(st.out[slots, K.C_DDOT].max())
            if math.isnan(self.impact_speed):
                self.impact_speed = w_n
            peak = K.n_stiff(md.mass, w_n, md.sc.contact.b_p, md.sc.contact.k_p)
            self.impacts.append((t, w_n, peak))
        self.had_fence = fence_on
        n = res[K.R_FENCE_N]
        if n > self.peak_n:
            self.peak_n = n
        # a local maximum of N at the previous point: the parabola through the last three
        # points recovers the peak between steps (third-order accurate; adaptive steps), if
        # the same contacts carried the force at all three (N is smooth there; across an
        # event, e.g. a corner sliding off the tip, it is not)
        n1, n2 = self.last_n[1], self.last_n[2]
        masks = self.last_mask
        smooth = masks[0] == masks[1] == mask
        masks[0], masks[1] = masks[1], mask
        if smooth and n2 > n1 and n2 >= n and n1 > 0.0:
            t0, t1 = self.last_t[1], self.last_t[2]
            peak = K.parabola_peak(t0, n1, t1, n2, t, n)
            if peak > self.peak_n:
                self.peak_n = peak
        self.last_n[1], self.last_n[2] = n2, n
        self.last_t[1], self.last_t[2] = self.last_t[2], t
        tip = abs(res[K.R_TIP_W])
        if tip > self.peak_tip:
            self.peak_tip = tip
        if res[K.R_MAX_D] > self.max_depth:
            self.max_depth = res[K.R_MAX_D]
        if y[1] > self.y_max:
            self.y_max = y[1]
        if mask != self.mask or (self.sorted and self.stage != STAGE_SORTED):
            self.mask = mask
            stage = (
                STAGE_SORTED if self.sorted else classify(st.out, md.normals, y[2], self.touched)
            )
            if stage != self.stage:
                self.stage = stage
                self.stages.append((stage, t))
        if self.want:
            self._record(st)
        self.prev_t = t
        self.prev_y[:] = y[:6]
        self.prev_power = power
        return self.sorted and self.stop_when_sorted, on_belt and not self.sorted

    def _record(self, st) -> None:
        rec, want, y = self.rec, self.want, st.y
        if "trajectory" in want:
            rec.setdefault("t", []).append(st.t)
            for k, key in enumerate(("x", "y", "phi", "vx", "vy", "phidot")):
                rec.setdefault(key, []).append(y[k])
        if "fence" in want:
            rec.setdefault("t_fence", []).append(st.t)
            rec.setdefault("alpha_w", []).append(st.res[K.R_ALPHA])
            rec.setdefault("tip_deflection", []).append(st.res[K.R_TIP_W])
        if "forces" in want:
            rec.setdefault("t_forces", []).append(st.t)
            rec.setdefault("normal_force", []).append(st.res[K.R_FENCE_N])
            rec.setdefault("deformation", []).append(st.res[K.R_MAX_D])
        if "stages" in want:
            rec.setdefault("t_stage", []).append(st.t)
            rec.setdefault("stage", []).append(self.stage)

    def result(self, t, diagnosis, steps, rejected, wall, forced=0, events=0) -> SimulationResult:
        return make_result(
            self.md, t, diagnosis, steps, rejected, wall, forced, events,
            sorted_=self.sorted, touched=self.touched, exit_speed=self.exit_speed,
            impact_speed=self.impact_speed, impacts=self.impacts, peak_n=self.peak_n,
            peak_tip=self.peak_tip, max_depth=self.max_depth, y_max=self.y_max,
            stages=self.stages, audit=self.audit,
            series={k: np.asarray(v) for k, v in self.rec.items()},
        )  # fmt: skip


def make_result(
    md: SortingModel, t, diagnosis, steps, rejected, wall, forced, events, *, sorted_, touched,
    exit_speed, impact_speed, impacts, peak_n, peak_tip, max_depth, y_max, stages, audit, series,
) -> SimulationResult:  # fmt: skip
    """The :class:`SimulationResult` of a run from its reductions (``Observer.result``; the
    compiled loop's driver calls it with the loop's figures directly)."""
    width = md.sc.conveyor.width
    success = diagnosis is None
    if not success:
        reason = "solver failure: " + diagnosis
    elif sorted_:
        reason = "sorted: centre of gravity crossed the chute edge y0 = s"
    elif not touched:
        reason = "not sorted: the fence never touched the load"
    else:
        reason = f"not sorted: y_max = {y_max:.3f} m < s = {width:g} m"
    return SimulationResult(
        success=success,
        sorted=sorted_ and success,
        reason=reason,
        diagnosis=diagnosis,
        peak_contact_force=peak_n,
        peak_contact_force_stiff=max((p for _, _, p in impacts), default=0.0),
        peak_normal_accel=peak_n / md.mass,
        impact_normal_speed=impact_speed,
        exit_speed_y=exit_speed,
        y_max=y_max,
        peak_tip_deflection=peak_tip,
        stages=stages,
        sim_time=t,
        wall_time=wall,
        steps=steps,
        rejected_steps=rejected,
        forced_steps=forced,
        method=md.sc.solver.method,
        events=events,
        energy_excess=audit.max_residual,
        energy=audit,
        max_penetration=max_depth,
        impacts=impacts,
        series=series,
        model_parts=md.parts,
    )
