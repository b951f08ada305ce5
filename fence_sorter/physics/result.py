"""What one sorting event produced: :class:`SimulationResult` with its :class:`EnergyAudit`
(the load's energy never rises above the work its power sources did on it). The solve loop's
reductions (``kernel.observe``: peaks, impact speed, N_stiff, stages, the audit) fill it through
:func:`make_result`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .model import SortingModel


@dataclass
class EnergyAudit:
    """The balance r(t) = E_load(t) - E_load(0) - W_sources(t), both ways, and E_flow.

    E_load is kinetic energy plus sum k_p D^5 / 5; W_sources the work of the fence surface
    velocity on the contact forces, of the belt velocity on the belt friction, and of the
    external wrench (trapezoidal quadrature over the accepted points). Energy never rises
    without a source: r never grows over any interval ([t1, t2], ``max_rise``); in the elastic
    limit it stays ~0 both ways. E_flow = E_load(0) + integral |P_sources| dt scales the
    quadrature's tolerance. The solve loop updates it at every accepted point
    (``kernel.observer._audit``).
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


def make_result(
    md: SortingModel, t, diagnosis, steps, rejected, wall, forced, events, *, sorted_, touched,
    exit_speed, impact_speed, impacts, peak_n, peak_tip, max_depth, y_max, stages, audit, series,
) -> SimulationResult:  # fmt: skip
    """The :class:`SimulationResult` of a run from its reductions (``Stepper.result`` calls it
    with the solve loop's figures)."""
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
