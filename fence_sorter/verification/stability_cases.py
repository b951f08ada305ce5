"""The stability campaign's cases: shipped scenes with dotted-key overrides (the CLI's ``--set``)
and what each must do (:mod:`fence_sorter.verification.stability` runs them; the expectations
and invariants are described there)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass, field

from fence_sorter.codes import Stage

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
    item: str = ""  # the required range this case covers (REQUIRED_RANGES)
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
        return [f"{k}={yaml_value(v)}" for k, v in items.items()]


def yaml_value(v: object) -> str:
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


def refined_solver(sv):
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
