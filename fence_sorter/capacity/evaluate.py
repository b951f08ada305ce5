"""One candidate stroke (R_s, t1, alpha_k) for one load, evaluated on the twin.

:func:`evaluate_stroke` runs the physics core once (``simulate``) and reduces it to a
:class:`StrokeEvaluation`: the margins of (7)-(12), the capacity W_t (1) with Delta_c (2) and
the figures a fence command predicts. Shared by the controller's planner and the optimiser.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from fence_sorter.capacity.constraints import (
    CONSTRAINT_TEXT,
    ConstraintProfile,
    footprint_length,
    margins,
    violated,
)
from fence_sorter.capacity.formulas import pitch
from fence_sorter.physics.params import ParcelParams
from fence_sorter.physics.simulate import Scenario, SimulationResult, simulate

DEFAULT_PROFILE = ConstraintProfile()

#: Solver settings for planning: looser than the scenes' (peak figures agree within ~3 %,
#: see test/capacity), several times faster.
PLANNING_RTOL = 3e-4
PLANNING_DT_MAX = 2e-2
PLANNING_SETTLE = 0.15


def planning_scenario(
    base: Scenario,
    *,
    fence: str = "stiff",
    rtol: float = PLANNING_RTOL,
    dt_max: float = PLANNING_DT_MAX,
) -> Scenario:
    """The scenario the planner evaluates: stiff fence of the same length (or the scene's own
    fence with ``fence="scene"``), no recorded series, stop when sorted, looser tolerances."""
    if fence not in ("stiff", "scene"):
        raise ValueError(f"fence must be 'stiff' or 'scene', got {fence!r}")
    sc = base
    if fence == "stiff" and sc.fence is not None:
        sc = replace(sc, fence=None, fence_length=sc.fence.length, fence_modes=None)
    solver = replace(
        sc.solver,
        rtol=rtol,
        dt_max=dt_max,
        settle_time=min(sc.solver.settle_time, PLANNING_SETTLE),
        stop_when_sorted=True,
        t_end=0.0,
    )
    return replace(sc, solver=solver, record=())


@dataclass(frozen=True)
class StrokeEvaluation:
    """A stroke evaluated on the twin: feasibility under the active constraints and W_t."""

    r_s: float
    t1: float
    alpha_k: float
    feasible: bool
    margins: dict[int, float]
    active: tuple[int, ...]
    violated: tuple[int, ...]
    capacity_pcs_h: float  # W_t (1)
    delta_c: float  # Delta_c (2) [m]
    sorted: bool
    impact_speed: float  # w_n [m/s]
    peak_accel: float  # a_N [m/s^2]
    exit_speed: float  # ydot at y0 = s [m/s] (NaN if not sorted)
    peak_force: float  # N [N]
    y_max: float  # y_k [m]
    diagnosis: str
    wall_time: float = 0.0
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        def num(v):
            return float(v) if math.isfinite(v) else None

        return {
            "r_s": self.r_s,
            "t1": self.t1,
            "alpha_k": self.alpha_k,
            "feasible": self.feasible,
            "margins": {str(k): num(v) for k, v in self.margins.items()},
            "active": list(self.active),
            "violated": list(self.violated),
            "W_t": num(self.capacity_pcs_h),
            "delta_c": num(self.delta_c),
            "sorted": self.sorted,
            "impact_speed": num(self.impact_speed),
            "peak_accel": num(self.peak_accel),
            "exit_speed": num(self.exit_speed),
            "peak_force": num(self.peak_force),
            "y_max": num(self.y_max),
            "diagnosis": self.diagnosis,
        }


def diagnose(margin: dict[int, float], bad: tuple[int, ...]) -> str:
    """One line naming each violated constraint with its margin."""
    if not bad:
        return "feasible"
    parts = []
    for c in bad:
        m = margin.get(c, math.nan)
        parts.append(f"{CONSTRAINT_TEXT[c]} violated by {m:.3g}")
    return "; ".join(parts)


def evaluate_stroke(
    base: Scenario,
    parcel: ParcelParams,
    r_s: float,
    t1: float,
    alpha_k: float,
    profile: ConstraintProfile = DEFAULT_PROFILE,
    *,
    gap: float = 0.0,
    a_max: float | None = None,
    mu_belt: float | None = None,
    mu_fence: float | None = None,
) -> StrokeEvaluation:
    """Simulate ``parcel`` under the stroke (R_s, t1, alpha_k) on ``base`` and judge it.

    ``base`` is used as given (pass :func:`planning_scenario` for the fast planning settings);
    W_t (1) uses Delta_c (2) with A_max = ``a_max`` (default: the load's own extent along the
    belt) and the gap Delta = ``gap``. ``mu_belt``/``mu_fence`` override the scene's mu1/mu2.
    """
    conveyor = base.conveyor
    if mu_belt is not None and math.isfinite(mu_belt):
        conveyor = replace(conveyor, mu_belt=mu_belt)
    contact = base.contact
    if mu_fence is not None and math.isfinite(mu_fence):
        contact = replace(contact, mu_fence=mu_fence)
    drive = replace(base.drive, r_s=r_s, t1=t1, alpha_k=alpha_k)
    sc = replace(base, conveyor=conveyor, contact=contact, drive=drive, parcel=parcel)
    v = conveyor.belt_speed
    extent = footprint_length(parcel)
    delta_c = pitch(v, t1, r_s, a_max if a_max is not None else extent, gap)
    w_t = 3600.0 * v / delta_c
    try:
        parcel.validate(belt_width=conveyor.width)
        drive.validate()
        res: SimulationResult = simulate(sc)
    except (ValueError, ArithmeticError) as exc:
        return _failed(r_s, t1, alpha_k, profile, w_t, delta_c, f"invalid stroke or load: {exc}")
    if not res.success:
        return _failed(r_s, t1, alpha_k, profile, w_t, delta_c, f"solver failure: {res.diagnosis}")
    m = margins(
        res,
        parcel,
        r_s=r_s,
        t1=t1,
        alpha_k=alpha_k,
        v=v,
        belt_width=conveyor.width,
        fence_length=base.length,
        profile=profile,
    )
    bad = violated(m, profile.active)
    return StrokeEvaluation(
        r_s=r_s,
        t1=t1,
        alpha_k=alpha_k,
        feasible=not bad,
        margins=m,
        active=tuple(profile.active),
        violated=bad,
        capacity_pcs_h=w_t,
        delta_c=delta_c,
        sorted=res.sorted,
        impact_speed=res.impact_normal_speed,
        peak_accel=res.peak_normal_accel,
        exit_speed=res.exit_speed_y,
        peak_force=res.peak_contact_force,
        y_max=res.y_max,
        diagnosis=diagnose(m, bad),
        wall_time=res.wall_time,
    )


def _failed(r_s, t1, alpha_k, profile, w_t, delta_c, why: str) -> StrokeEvaluation:
    nan = math.nan
    return StrokeEvaluation(
        r_s=r_s,
        t1=t1,
        alpha_k=alpha_k,
        feasible=False,
        margins={c: nan for c in profile.active},
        active=tuple(profile.active),
        violated=tuple(profile.active),
        capacity_pcs_h=w_t,
        delta_c=delta_c,
        sorted=False,
        impact_speed=nan,
        peak_accel=nan,
        exit_speed=nan,
        peak_force=nan,
        y_max=nan,
        diagnosis=why,
    )
