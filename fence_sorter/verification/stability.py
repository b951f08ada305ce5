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
writes ``README.md``, ``results.json`` and ``summary.png`` into ``docs/stability/``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fence_sorter.codes import Stage
from fence_sorter.physics.params import ParameterError
from fence_sorter.physics.simulate import EnergyAudit, SortingModel, simulate
from fence_sorter.scene import load_scene
from fence_sorter.verification.machine import git_revision, machine_info
from fence_sorter.verification.report import table

__all__ = [
    "CASES",
    "Case",
    "CaseResult",
    "Invariant",
    "case_names",
    "fast_cases",
    "git_revision",
    "grazing_r_s",
    "machine_info",
    "run_case",
    "run_cases",
    "select_cases",
    "warm_up",
]

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
DEFAULT_WALL = 60.0  # [s] solver.max_wall_time of a case

# diagnoses the solver names (stepper.Failure, stepper.diagnosis_text)
KNOWN_CAUSES = (
    "step size fell below solver.min_dt",
    "deep penetration",
    "load speed",
    "non-finite state",
    "wall-time limit",
)

FAST, SLOW = "fast", "slow"
PASS, FAIL, DIAGNOSED = "PASS", "FAIL", "DIAGNOSED"
EXPECTATIONS = ("pass", "diagnosed", "warning")


@dataclass(frozen=True)
class Case:
    """One stability case: a scene, its overrides, what must happen, how long it may take."""

    name: str
    description: str
    scene: str
    overrides: dict[str, object] = field(default_factory=dict)
    expected: str = "pass"  # pass | diagnosed | warning
    item: str = ""  # the issue's item this case covers
    speed: str = FAST  # fast: in the CI subset (--quick); slow: full campaign only
    max_wall_time: float = DEFAULT_WALL
    cause: str = ""  # expected "diagnosed": a word of the diagnosis naming the cause
    warning: str = ""  # expected "warning": a word of the scene loader's warning
    elastic: bool = False  # check the energy balance both ways
    convergence: bool = True
    # solver overrides of a fine reference solve the result must also agree with (grazing)
    reference: dict[str, object] = field(default_factory=dict)
    stage: str = ""  # a stage the event must reach (the case exercises what it claims)
    note: str = ""  # longer justification (geometry, why it is expected to fail)

    def __post_init__(self) -> None:
        if self.expected not in EXPECTATIONS:
            raise ValueError(f"case {self.name}: expected must be one of {EXPECTATIONS}")
        if self.speed not in (FAST, SLOW):
            raise ValueError(f"case {self.name}: speed must be {FAST!r} or {SLOW!r}")

    def override_strings(self) -> list[str]:
        """The ``key=value`` overrides for ``load_scene``, with the case's wall-time limit."""
        items = dict(self.overrides)
        items.setdefault("solver.max_wall_time", self.max_wall_time)
        return [f"{k}={_yaml_value(v)}" for k, v in items.items()]


def _yaml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        short = f"{v:g}"  # the scene loader accepts numeric strings such as 1e-09
        return short if float(short) == v else repr(v)  # repr round-trips exactly
    return str(v)


# -- the grazing geometry -------------------------------------------------------------------------
def grazing_r_s(
    *,
    length: float,
    lateral_gap: float,
    length_a: float,
    belt_speed: float,
    alpha_k: float,
    t1: float,
    overlap: float = 0.0,
) -> float:
    """R_s that makes the stiff fence's tip just reach the load's rear fence-side corner.

    The fence root is the origin, the fence swings from the +x0 axis by alpha_w(t) =
    (alpha_k/2)(1 - cos(pi t/t1)); the load (yaw 0) rides the belt at belt_speed with its
    fence-side face on y0 = gap and its rear face at x_r(t) = R_s - A + v t. Its rear fence-side
    corner (x_r, gap) is the load's point nearest to the root, and its distance grows with t.
    The fence line sweeps that corner when alpha_w(t*) equals the corner's polar angle; we want
    the corner at radius R_z - overlap then: alpha* = asin(gap / (R_z - overlap)),
    t* = (t1/pi) acos(1 - 2 alpha*/alpha_k), x* = (R_z - overlap) cos(alpha*), and
    R_s = x* - v t* + A. Before t* the fence's intersection with the face y0 = gap lies beyond
    R_z (alpha_w < alpha*, radius gap / sin(alpha_w) > R_z); after t* the corner is beyond the tip.
    With overlap = 0 the only common point is the tip on the corner at t*, a zero-depth graze;
    with overlap > 0 the corner crosses the fence line ``overlap`` inside the tip and slides off.
    """
    r = length - overlap
    if not 0.0 < lateral_gap < r:
        raise ValueError("grazing needs 0 < lateral_gap < R_z - overlap")
    alpha_star = math.asin(lateral_gap / r)
    if alpha_star >= alpha_k:
        raise ValueError("the fence never reaches the corner's angle (alpha* >= alpha_k)")
    t_star = (t1 / math.pi) * math.acos(1.0 - 2.0 * alpha_star / alpha_k)
    x_star = r * math.cos(alpha_star)
    return x_star - belt_speed * t_star + length_a


# arbitrary_stiff's values, restated so the grazing R_s does not depend on the file's contents
_GRAZE = {
    "fence.length": 1.4,
    "drive.alpha_k_deg": 35.0,
    "drive.t1": 0.7,
    "conveyor.belt_speed": 1.75,
    "parcel.length_a": 0.1,
    "parcel.width_b": 0.1,
    "parcel.lateral_gap": 0.6,
    "parcel.yaw_deg": 0.0,
    "parcel.cog": "centre",
}


def _graze(overlap: float) -> dict[str, object]:
    r_s = grazing_r_s(
        length=_GRAZE["fence.length"],
        lateral_gap=_GRAZE["parcel.lateral_gap"],
        length_a=_GRAZE["parcel.length_a"],
        belt_speed=_GRAZE["conveyor.belt_speed"],
        alpha_k=math.radians(_GRAZE["drive.alpha_k_deg"]),
        t1=_GRAZE["drive.t1"],
        overlap=overlap,
    )
    return {**_GRAZE, "drive.r_s": r_s}


# the fine reference of the grazing cases: 0.1 ms steps resolve a contact of about 1 ms
_FINE = {"solver.dt_max": 1e-4, "solver.dt": 1e-4}

_GRAZE_NOTE = (
    "Stiff fence R_z = 1.4 m, alpha_k = 35 deg, t1 = 0.7 s, belt 1.75 m/s, 0.1 x 0.1 m load at "
    "gap 0.6 m (arbitrary_stiff). The load's rear fence-side corner is its point nearest to the "
    "fence root; R_s is chosen so the fence line sweeps that corner exactly when it is at radius "
    "R_z - overlap: alpha* = asin(0.6 / (R_z - overlap)) = 25.4 deg, reached at t* = (t1/pi) "
    "acos(1 - 2 alpha*/alpha_k) = 0.454 s, corner at x* = (R_z - overlap) cos(alpha*), "
    "R_s = x* - v t* + A (``stability.grazing_r_s``). Before t* the fence meets y0 = gap beyond "
    "its tip, after t* the corner is beyond the tip."
)

# -- the campaign ---------------------------------------------------------------------------------
_ELASTIC = {
    "contact.b_p": 0.0,
    "conveyor.mu_belt": 0.0,
    "contact.mu_fence": 0.0,
}
_KARNOPP = {"1e-3": 1e-3, "1e-6": 1e-6, "1e-9": 1e-9}

CASES: tuple[Case, ...] = (
    # -- fence meshes up to 50 elements ------------------------------------------------------
    *(
        Case(
            f"mesh_{n}",
            f"impact_flexible with a {n}-element fence (all {2 * n} modes kept)",
            "impact_flexible",
            {"fence.elements": n},
            item="fence meshes up to 50 elements",
            speed=FAST if n <= 25 else SLOW,
        )
        for n in (2, 10, 25, 50)
    ),
    # -- contact stiffness k_p x 1000 ---------------------------------------------------------
    Case(
        "kp_x1000_flexible",
        "impact_flexible with k_p = 1.72e12 N/m^4 (x1000)",
        "impact_flexible",
        {"contact.k_p": 1.72e12},
        item="contact stiffness k_p x1000",
    ),
    Case(
        "kp_x1000_mesh_50",
        "impact_flexible with k_p x1000 on a 50-element fence (stiffest combination)",
        "impact_flexible",
        {"contact.k_p": 1.72e12, "fence.elements": 50},
        item="contact stiffness k_p x1000",
        speed=SLOW,
    ),
    Case(
        "kp_x1000_stiff",
        "positioned_stiff with k_p = 1.72e12 N/m^4 (x1000)",
        "positioned_stiff",
        {"contact.k_p": 1.72e12},
        item="contact stiffness k_p x1000",
        note=(
            "The load rattles on the two stiff corner contacts at ~26 Hz with mm amplitude, "
            "almost undamped (omega ~270 rad/s, damping ratio of law (16) ~0.003; 0.1-0.4 at "
            "the paper's k_p). Milne's estimate (positions scaled by 1 m) does not see it and "
            "the trapezoidal phase lag ((omega h)^2 / 12 per radian) left the peak N 3.5 % "
            "low (90.7 N against 94.0 N at dt = 1e-5 s; failed convergence, 2.6 % against "
            "2.4 %). kernel.oscillation_step caps omega h <= 10 sqrt(rtol) on contacts damped "
            "below zeta = 0.02 (the bench scenes never meet it): 93.1 N, 258 -> 786 steps."
        ),
    ),
    Case(
        "kp_x1000_slide",
        "slide_flexible with k_p = 1.72e12 N/m^4 (x1000), load sliding along the fence",
        "slide_flexible",
        {"contact.k_p": 1.72e12},
        item="contact stiffness k_p x1000",
    ),
    # -- parcel masses 0.1 kg to 60 kg --------------------------------------------------------
    *(
        Case(
            f"mass_{label}",
            f"impact_flexible with a {m:g} kg load",
            "impact_flexible",
            {"parcel.mass": m},
            item="parcel masses 0.1 kg to 60 kg",
        )
        for label, m in (("0p1", 0.1), ("1", 1.0), ("15", 15.0), ("60", 60.0))
    ),
    # -- belt speeds --------------------------------------------------------------------------
    Case(
        "belt_0p2",
        "impact_flexible at belt speed 0.2 m/s (bottom of range (4))",
        "impact_flexible",
        {"conveyor.belt_speed": 0.2},
        item="belt 0.2 and 2.5 m/s",
    ),
    Case(
        "belt_2p5",
        "impact_flexible at belt speed 2.5 m/s (top of range (4))",
        "impact_flexible",
        {"conveyor.belt_speed": 2.5},
        item="belt 0.2 and 2.5 m/s",
    ),
    Case(
        "belt_5",
        "impact_flexible at 5 m/s, beyond range (4): must warn, then pass or be diagnosed",
        "impact_flexible",
        {"conveyor.belt_speed": 5.0},
        expected="warning",
        warning="outside the paper's range (4)",
        item="belt beyond the range (5 m/s)",
    ),
    # -- t1 = 0.1 s with alpha_k = 60 deg ---------------------------------------------------------
    Case(
        "fast_drive_flexible",
        "impact_flexible with t1 = 0.1 s, alpha_k = 60 deg (tip speed 13 m/s)",
        "impact_flexible",
        {"drive.t1": 0.1, "drive.alpha_k_deg": 60.0},
        item="t1 = 0.1 s with alpha_k = 60 deg",
        speed=SLOW,
    ),
    Case(
        "fast_drive_stiff",
        "positioned_stiff with t1 = 0.1 s, alpha_k = 60 deg",
        "positioned_stiff",
        {"drive.t1": 0.1, "drive.alpha_k_deg": 60.0},
        item="t1 = 0.1 s with alpha_k = 60 deg",
    ),
    # -- friction extremes ------------------------------------------------------------------------
    Case(
        "mu1_0",
        "impact_flexible with a frictionless belt (mu1 = 0)",
        "impact_flexible",
        {"conveyor.mu_belt": 0.0},
        item="mu1, mu2 = 0 and 1.2",
    ),
    Case(
        "mu1_1p2",
        "impact_flexible with mu1 = 1.2",
        "impact_flexible",
        {"conveyor.mu_belt": 1.2},
        item="mu1, mu2 = 0 and 1.2",
    ),
    Case(
        "mu2_0",
        "impact_flexible with a frictionless fence and border (mu2 = 0)",
        "impact_flexible",
        {"contact.mu_fence": 0.0},
        item="mu1, mu2 = 0 and 1.2",
    ),
    Case(
        "mu2_1p2",
        "impact_flexible with mu2 = 1.2 (beyond atan(1/mu2) < alpha_k: border built)",
        "impact_flexible",
        {"contact.mu_fence": 1.2},
        item="mu1, mu2 = 0 and 1.2",
        speed=SLOW,
    ),
    Case(
        "mu2_1p2_slide",
        "slide_flexible with mu2 = 1.2 (sliding along the fence, sticking on it)",
        "slide_flexible",
        {"contact.mu_fence": 1.2},
        item="mu1, mu2 = 0 and 1.2",
        speed=SLOW,
    ),
    Case(
        "mu1_mu2_1p2_stiff",
        "positioned_stiff with mu1 = mu2 = 1.2",
        "positioned_stiff",
        {"conveyor.mu_belt": 1.2, "contact.mu_fence": 1.2},
        item="mu1, mu2 = 0 and 1.2",
    ),
    # -- parcel sizes -----------------------------------------------------------------------------
    Case(
        "parcel_0p02",
        "impact_flexible with a 0.02 m cube of 0.01 kg",
        "impact_flexible",
        {
            "parcel.length_a": 0.02,
            "parcel.width_b": 0.02,
            "parcel.height": 0.02,
            "parcel.mass": 0.01,
        },
        item="parcels 0.02 m and 1.2 m long",
    ),
    Case(
        "parcel_0p02_heavy",
        "impact_flexible with a 0.02 x 0.3 m load of 15 kg: D > half its 0.02 m side",
        "impact_flexible",
        {"parcel.length_a": 0.02},
        expected="diagnosed",
        cause="deep penetration",
        item="parcels 0.02 m and 1.2 m long",
        note=(
            "A 15 kg load hitting at w_n = 2.4 m/s deforms the contact law (16) by "
            "(5 m w_n^2 / (2 k_p))^(1/5) = 2.9 cm against a rigid wall, more than half of the "
            "load's 0.02 m length: the paper's law is outside its validity for this load, so the "
            "solve must stop with a deep-penetration diagnosis instead of pushing the fence "
            "through the load."
        ),
    ),
    Case(
        "parcel_1p2",
        "impact_flexible with a 1.2 m long load",
        "impact_flexible",
        {"parcel.length_a": 1.2},
        item="parcels 0.02 m and 1.2 m long",
    ),
    Case(
        "parcel_1p2_stiff",
        "positioned_stiff with a 1.2 x 0.1 m load, C_s on the rear fence-side corner",
        "positioned_stiff",
        {"parcel.length_a": 1.2, "drive.r_s": 1.2},
        item="parcels 0.02 m and 1.2 m long",
    ),
    # -- grazing contact --------------------------------------------------------------------------
    *(
        Case(
            f"grazing_{label}",
            f"stiff fence tip reaching {text} the load's nearest corner",
            "arbitrary_stiff",
            _graze(overlap),
            item="grazing contact",
            reference=_FINE,
            note=_GRAZE_NOTE + f" Here overlap = {overlap * 1e3:g} mm: {detail}",
        )
        for label, overlap, text, detail in (
            ("exact", 0.0, "exactly (zero depth)", "a zero-depth touch, no force."),
            (
                "1mm",
                1e-3,
                "1 mm past",
                "the corner crosses the fence line and slides off the tip within about 1 ms.",
            ),
            ("5mm", 5e-3, "5 mm past", "a shallow contact of a few ms that nudges the load."),
        )
    ),
    # -- zero damping -----------------------------------------------------------------------------
    Case(
        "zero_damping",
        "impact_flexible with b_p = 0 and fence damping_ratio = 0",
        "impact_flexible",
        {"contact.b_p": 0.0, "fence.damping_ratio": 0.0},
        item="zero damping",
    ),
    Case(
        "elastic_flexible",
        "impact_flexible, elastic limit: b_p = 0, mu1 = mu2 = 0, damping_ratio = 0",
        "impact_flexible",
        {**_ELASTIC, "fence.damping_ratio": 0.0},
        elastic=True,
        item="zero damping",
    ),
    Case(
        "elastic_stiff",
        "positioned_stiff, elastic limit: b_p = 0, mu1 = mu2 = 0",
        "positioned_stiff",
        dict(_ELASTIC),
        elastic=True,
        item="zero damping",
    ),
    # -- parcel exactly on the border (E3) --------------------------------------------------------
    Case(
        "border_flexible",
        "impact_flexible with the load exactly on the border (lateral_gap = 0)",
        "impact_flexible",
        {"parcel.lateral_gap": 0.0},
        item="a parcel exactly on the border (E3)",
        stage=Stage.E3.label,
    ),
    Case(
        "border_stiff",
        "positioned_stiff (gap 0) at alpha_k = 75 deg > atan(1/mu2): fence friction holds it on "
        "the border",
        "positioned_stiff",
        {"drive.alpha_k_deg": 75.0},
        item="a parcel exactly on the border (E3)",
        stage=Stage.E3.label,
    ),
    Case(
        "border_slide",
        "slide_flexible: the load starts on the border (gap 0) and slides along the fence",
        "slide_flexible",
        {},
        item="a parcel exactly on the border (E3)",
        stage=Stage.E3.label,
    ),
    # -- Karnopp thresholds -----------------------------------------------------------------------
    *(
        Case(
            f"karnopp_{label}_slide",
            f"slide_flexible with v_min = phidot_min = {label}",
            "slide_flexible",
            {"contact.v_min": v, "contact.phidot_min": v},
            item="Karnopp thresholds 1e-3 to 1e-9",
        )
        for label, v in _KARNOPP.items()
    ),
    *(
        Case(
            f"karnopp_{label}_stiff",
            f"positioned_stiff with v_min = phidot_min = {label}",
            "positioned_stiff",
            {"contact.v_min": v, "contact.phidot_min": v},
            item="Karnopp thresholds 1e-3 to 1e-9",
        )
        for label, v in (("1e-3", 1e-3), ("1e-9", 1e-9))
    ),
    # -- the fixed-step methods on the default scene ----------------------------------------------
    Case(
        "trapezoidal",
        "impact_flexible with solver.method = trapezoidal (fixed dt = 0.5 ms)",
        "impact_flexible",
        {"solver.method": "trapezoidal"},
        item="results converge when the step is halved",
    ),
    Case(
        "generalized_alpha",
        "impact_flexible with solver.method = generalized_alpha (dt = 0.5 ms, rho_inf 0.8)",
        "impact_flexible",
        {"solver.method": "generalized_alpha"},
        item="results converge when the step is halved",
    ),
    # -- cases that cannot be solved --------------------------------------------------------------
    Case(
        "diverging_trapezoidal",
        "deliberately diverging: trapezoidal, k_p = 1e16, 2 iterations, dt = 5 ms, min_dt = 1 ms",
        "impact_flexible",
        {
            "solver.method": "trapezoidal",
            "contact.k_p": 1e16,
            "solver.dt": 5e-3,
            "solver.min_dt": 1e-3,
            "solver.max_iterations": 2,
        },
        expected="diagnosed",
        cause="min_dt",
        item="a case that cannot be solved ends with a clear diagnosis",
        note=(
            "k_p = 1e16 N/m^4 (x 6e6) with the contact iteration capped at 2 cannot converge "
            "at any step the coarse 5 ms grid can halve to before min_dt = 1 ms: the solve "
            "must stop with the min_dt diagnosis at the first contact. (With the default 12 "
            "accelerated iterations the A-stable trapezoidal step does solve it.)"
        ),
    ),
    Case(
        "wall_time_limit",
        "deliberately too slow: adaptive at rtol 1e-12, dt_max 1 us, 0.5 s wall limit",
        "impact_flexible",
        {"solver.rtol": 1e-12, "solver.atol": 1e-14, "solver.dt_max": 1e-6, "solver.dt": 1e-6},
        expected="diagnosed",
        cause="wall-time",
        max_wall_time=0.5,
        item="none hangs (each bounded in time)",
        note=(
            "A solve that would take hours (1.2 s at 1 us steps) must stop at its wall-time "
            "limit with a diagnosis instead of hanging the campaign."
        ),
    ),
)


def case_names() -> list[str]:
    return [c.name for c in CASES]


def fast_cases() -> list[Case]:
    return [c for c in CASES if c.speed == FAST]


def select_cases(names: Iterable[str] | None = None, quick: bool = False) -> list[Case]:
    """Cases by name (in campaign order), or the fast subset, or all; KeyError on a bad name."""
    pool = fast_cases() if quick else list(CASES)
    if not names:
        return pool
    wanted = list(dict.fromkeys(names))
    by_name = {c.name: c for c in CASES}
    unknown = [n for n in wanted if n not in by_name]
    if unknown:
        raise KeyError(", ".join(unknown))
    keep = set(wanted)
    return [c for c in CASES if c.name in keep]


def _refined_solver(sv):
    """The same solve with the step halved (adaptive: tolerances / 10 as well)."""
    if sv.method == "adaptive":
        new = dataclasses.replace(
            sv,
            rtol=sv.rtol / 10.0,
            atol=sv.atol / 10.0,
            dt_max=sv.dt_max / 2.0,
            dt=sv.dt / 2.0,
            min_dt=min(sv.min_dt, sv.dt / 2.0),
        )
    else:
        new = dataclasses.replace(sv, dt=sv.dt / 2.0, min_dt=min(sv.min_dt, sv.dt / 2.0))
    new.validate()
    return new


def refinement_text(sv) -> str:
    if sv.method == "adaptive":
        return "rtol/10, atol/10, dt_max/2, dt/2"
    return "dt/2"


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
                + [f"{k}={_yaml_value(v)}" for k, v in case.reference.items()],
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
            sc2 = dataclasses.replace(sc, solver=_refined_solver(sc.solver))
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


# -- the report ----------------------------------------------------------------------------------
ISSUE_ITEMS = (
    "fence meshes up to 50 elements",
    "contact stiffness k_p x1000",
    "parcel masses 0.1 kg to 60 kg",
    "belt 0.2 and 2.5 m/s",
    "belt beyond the range (5 m/s)",
    "t1 = 0.1 s with alpha_k = 60 deg",
    "mu1, mu2 = 0 and 1.2",
    "parcels 0.02 m and 1.2 m long",
    "grazing contact",
    "zero damping",
    "a parcel exactly on the border (E3)",
    "Karnopp thresholds 1e-3 to 1e-9",
    "results converge when the step is halved",
    "a case that cannot be solved ends with a clear diagnosis",
    "none hangs (each bounded in time)",
)


def _fmt(v, spec: str = ".3g") -> str:
    if isinstance(v, str):
        return v
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:{spec}}"


def worst_ratio(cr: CaseResult, prefixes: tuple[str, ...] = ("conv_", "ref_")) -> float:
    """Largest |difference| / allowed over the numeric comparisons (nan if none)."""
    ratios = [
        i.value / i.limit
        for i in cr.invariants
        if i.name.startswith(prefixes)
        and isinstance(i.value, float)
        and isinstance(i.limit, float)
        and i.limit > 0
    ]
    return max(ratios) if ratios else math.nan


def results_json(results: Sequence[CaseResult], meta: dict) -> dict:
    return {**meta, "cases": [cr.to_dict() for cr in results]}


def plot_summary(results: Sequence[CaseResult], path) -> None:
    """One PNG: energy rise / tolerance, D_max / limit, worst convergence ratio, per case.

    A bar is green when its invariant holds and red when not; the case's verdict follows its
    name. Diagnosed cases have no values (nothing past a diagnosis is data).
    """
    import matplotlib  # lazy: Matplotlib (0.7-1.3 s), only to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: Matplotlib (0.7-1.3 s), only to plot

    n = len(results)
    floor, top = 1e-6, 100.0

    def energy(cr):
        inv = cr.invariant("energy")
        return (math.nan, True) if inv is None else (inv.value / inv.limit, inv.passed)

    def depth(cr):
        inv = cr.invariant("penetration")
        return (math.nan, True) if inv is None else (inv.value, inv.passed)

    def conv(cr):
        ok = all(i.passed for i in cr.invariants if i.name.startswith(("conv_", "ref_")))
        return worst_ratio(cr), ok

    panels = (
        ("energy rise / tolerance", energy),
        ("D_max / deep-penetration limit", depth),
        ("halved step, fine reference: |diff| / allowed (worst)", conv),
    )
    fig, axes = plt.subplots(1, 3, figsize=(15, 0.28 * n + 1.8), sharey=True)
    ypos = np.arange(n)[::-1]
    for ax, (title, fn) in zip(axes, panels, strict=True):
        for y, cr in zip(ypos, results, strict=True):
            v, ok = fn(cr)
            c = "tab:green" if ok else "tab:red"
            if not math.isfinite(v):
                label = "diagnosed" if cr.verdict == DIAGNOSED else "n/a"
                ax.text(floor * 1.5, y, label, va="center", fontsize=7, color="tab:orange")
                continue
            ax.barh(y, min(max(v, floor), top), left=0, color=c, height=0.7)
            if v <= floor:
                ax.text(floor * 1.5, y, "0", va="center", fontsize=7, color=c)
        ax.axvline(1.0, color="k", lw=1.0, ls="--")
        ax.set_xscale("log")
        ax.set_xlim(floor, top)
        ax.set_title(title, fontsize=9)
        ax.grid(True, axis="x", which="major", alpha=0.3)
    axes[0].set_yticks(ypos)
    labels = axes[0].set_yticklabels(
        [f"{cr.case.name} [{cr.verdict}]" for cr in results], fontsize=7
    )
    for lab, cr in zip(labels, results, strict=True):
        if not cr.meets_expectation:
            lab.set_color("tab:red")
    fig.suptitle(
        "fence-sorter stability: invariant value / limit per case (dashed: limit; red: violated)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _cell(inv: Mapping | None, spec: str = ".3g") -> str:
    """``value / limit`` of an invariant of results.json, a cross on a failed one."""
    if inv is None:
        return "-"
    value, limit = inv["value"], inv["limit"]
    if isinstance(value, str) and isinstance(limit, str):
        text = value
    else:
        text = f"{_fmt(_num(value), spec)} / {_fmt(_num(limit), spec)}"
    return text if inv["passed"] else f"**{text} ✗**"


def _num(v):
    """A number of results.json (non-finite ones are stored as "nan", "inf")."""
    return float(v) if v in ("nan", "inf", "-inf") else v


def render_readme(data: Mapping) -> str:
    """docs/stability/README.md from results.json alone: the run, the verdict table, the
    cases that missed their expectation, diagnoses and costly solves. What the verdicts and
    invariants mean: docs/verification.md."""
    cases = data["cases"]

    def inv(c: Mapping, name: str) -> Mapping | None:
        return next((i for i in c["invariants"] if i["name"] == name), None)

    counts = {v: sum(c["verdict"] == v for c in cases) for v in (PASS, DIAGNOSED, FAIL)}
    missed = [c for c in cases if not c["meets_expectation"]]
    mi = data["machine"]
    lines = [
        "# Stability campaign",
        "",
        "Generated by `fence-sorter stability` (`fence_sorter/verification/stability.py`) from "
        "`results.json`; do not edit by hand. `summary.png` is the overview. What the verdicts "
        "and invariants mean: [docs/verification.md](../verification.md#stability).",
        "",
        f"- command: `{data['command']}`",
        f"- date: {data['date']}, commit {data['commit']}",
        f"- machine: {mi['cpu']}, {mi['cores']} cores, {mi['os']}; Python {mi['python']}, "
        f"NumPy {mi['numpy']}, SciPy {mi['scipy']}, Numba {mi['numba']}",
        f"- {len(cases)} cases: {counts[PASS]} PASS, {counts[DIAGNOSED]} DIAGNOSED, "
        f"{counts[FAIL]} FAIL; {len(cases) - len(missed)} meet their expectation",
        f"- wall time: {data['wall_time_s']:.1f} s for the campaign "
        f"(plus {data['warm_up_s']:.1f} s compiling the kernel first)",
        "",
        "![summary](summary.png)",
        "",
        "## Results",
        "",
    ]
    head = [
        "case", "description", "expected", "verdict", "energy rise / tol [J]",
        "D_max / limit", "Δ peak N / allowed [N]", "Δ y_max / allowed [m]",
        "Δ exit / allowed [m/s]", "sorted (h, h/2)", "wall [s]", "method", "steps (rejected)",
    ]  # fmt: skip
    rows = []
    for c in cases:
        r, rr = c["result"], c["refined"]
        verdict = (
            c["verdict"]
            if c["meets_expectation"]
            else f"**{c['verdict']}** (expected {c['expected']})"
        )
        if r is None:
            sorted_cell = steps = method = "-"
        else:
            sorted_cell = "yes" if r["sorted"] else "no"
            if rr is not None:
                sorted_cell += ", " + ("yes" if rr["sorted"] else "no")
            steps = f"{r['steps']} ({r['rejected_steps']})"
            method = r["method"]
        pen = inv(c, "penetration")
        rows.append(
            [
                f"`{c['name']}`",
                c["description"],
                c["expected"],
                verdict,
                _cell(inv(c, "energy")),
                "-" if pen is None else _cell(pen, ".3f"),
                _cell(inv(c, "conv_peak_force")),
                _cell(inv(c, "conv_y_max")),
                _cell(inv(c, "conv_exit_speed")),
                sorted_cell,
                f"{c['wall_time_s']:.2f}",
                method,
                steps,
            ]
        )
    lines += table(head, rows)
    lines += ["", "## Cases that did not meet their expectation", ""]
    if not missed:
        lines.append("None.")
    for c in missed:
        sets = " ".join(f"--set {k}={_yaml_value(v)}" for k, v in c["overrides"].items())
        lines += [
            f"### `{c['name']}`: {c['verdict']} (expected {c['expected']})",
            "",
            f"{c['description']}. Reproduce: `fence-sorter simulate {c['scene']} {sets}`.",
            "",
        ]
        if c["error"]:
            lines.append(f"- error: `{c['error']}`")
        if c["diagnosis"]:
            lines.append(f"- diagnosis: {c['diagnosis']}")
        for i in c["invariants"]:
            if not i["passed"]:
                lines.append(
                    f"- `{i['name']}`: {_fmt(_num(i['value']))} against {_fmt(_num(i['limit']))}"
                    + (f"; {i['note']}" if i["note"] else "")
                )
        lines.append("")
    lines += ["## Diagnoses, warnings, other invariants", ""]
    for c in cases:
        extra = [f"warning: {w}" for w in c["warnings"]]
        if c["diagnosis"]:
            extra.append(f"diagnosis: {c['diagnosis']}")
        for name in ("energy_conserved", "stage"):
            i = inv(c, name)
            if i is not None:
                extra.append(
                    f"{name}: {_fmt(_num(i['value']))} against {_fmt(_num(i['limit']))}"
                    + ("" if i["passed"] else " (FAILED)")
                )
        refs = [i for i in c["invariants"] if i["name"].startswith("ref_")]
        if refs:
            extra.append(
                "reference: "
                + "; ".join(
                    f"{i['name']} {_fmt(_num(i['value']))} / {_fmt(_num(i['limit']))}"
                    + ("" if i["passed"] else " ✗")
                    for i in refs
                )
            )
        if c["result"] is not None:
            extra.append("stages: " + " → ".join(c["result"]["stages"]))
        if extra:
            lines.append(f"- `{c['name']}`: " + "; ".join(extra))
    slow = [
        c
        for c in cases
        if c["result"] is not None
        and max(c["result"]["wall_time_s"], (c["refined"] or {}).get("wall_time_s", 0.0)) > 2.0
    ]
    lines += ["", "## Costly solves (more than 2 s of wall time)", ""]
    if not slow:
        lines.append("None.")
    for c in slow:
        r, rr = c["result"], c["refined"]
        text = (
            f"- `{c['name']}`: {r['steps']} steps ({r['rejected_steps']} rejected) in "
            f"{r['wall_time_s']:.2f} s for {r['sim_time_s']:.3f} s simulated"
        )
        if rr is not None:
            text += (
                f"; at half the step ({c['refinement']}) {rr['steps']} steps "
                f"({rr['rejected_steps']} rejected) in {rr['wall_time_s']:.2f} s"
            )
        lines.append(text)
    notes = [c for c in cases if c.get("note")]
    if notes:
        lines += ["", "## Case notes", ""]
        lines += [f"- `{c['name']}`: {c['note']}" for c in notes]
    lines += ["", "## Coverage of the issue's items", ""]
    names_by_item: dict[str, list[str]] = {}
    for c in cases:
        names_by_item.setdefault(c["item"], []).append(c["name"])
    for item in ISSUE_ITEMS:
        got = names_by_item.get(item)
        lines.append(
            f"- {item}: " + (", ".join(f"`{n}`" for n in got) if got else "(not in this run)")
        )
    lines.append("")
    return "\n".join(lines)


def rerender(out_dir) -> Path:
    """README.md of ``out_dir`` from its results.json (no solve runs)."""
    out = Path(out_dir)
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    path = out / "README.md"
    path.write_text(render_readme(data), encoding="utf-8")
    return path


def write_report(results: Sequence[CaseResult], out_dir, meta: dict) -> dict[str, str]:
    """Write results.json, summary.png and README.md (rendered from results.json) into
    ``out_dir``; return their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "readme": out / "README.md",
        "json": out / "results.json",
        "png": out / "summary.png",
    }
    paths["json"].write_text(
        json.dumps(results_json(results, meta), indent=1, allow_nan=False, default=str) + "\n",
        encoding="utf-8",
    )
    plot_summary(results, paths["png"])
    rerender(out)
    return {k: str(v) for k, v in paths.items()}
