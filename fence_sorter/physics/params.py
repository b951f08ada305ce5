"""Parameter dataclasses of the sorting model (SI units, angles in rad).

Symbols follow the paper (Piatkowski & Sempruch, "Research of sorting process of unit loads by
rotary active fence"): alpha_k, t1, R_s, mu1, mu2, b_p, k_p keep the paper's names where it uses
them. Every dataclass has ``validate()`` that raises :class:`ParameterError` naming the field and
its allowed range, so a scene file or a ``--set`` override fails with a message, not a traceback.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

GRAVITY = 9.81


class ParameterError(ValueError):
    """A parameter is outside its allowed range; the message names the field."""


def check_range(
    name: str,
    value: float,
    lo: float,
    hi: float,
    *,
    lo_open: bool = False,
    unit: str = "",
) -> None:
    """Raise ParameterError unless ``lo <= value <= hi`` (``lo < value`` when lo_open)."""
    ok = isinstance(value, (int, float)) and math.isfinite(value)
    if ok:
        ok = (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        suffix = f" {unit}" if unit else ""
        raise ParameterError(f"{name} must be in {bracket}{lo:g}, {hi:g}]{suffix}, got {value!r}")


@dataclass(frozen=True)
class ConveyorParams:
    """Main conveyor: belt speed v (4), width s, belt friction mu1, the fence-side border wall."""

    belt_speed: float = 1.0  # v [m/s], paper range (4): 0.2-2.5
    width: float = 0.7  # s [m]
    mu_belt: float = 0.65  # mu1
    gravity: float = GRAVITY  # g [m/s^2]

    def validate(self, prefix: str = "conveyor") -> list[str]:
        """Check ranges; return warnings (speeds beyond the paper's range (4) are allowed)."""
        check_range(f"{prefix}.belt_speed", self.belt_speed, 0.0, 10.0, lo_open=True, unit="m/s")
        check_range(f"{prefix}.width", self.width, 0.05, 5.0, unit="m")
        check_range(f"{prefix}.mu_belt", self.mu_belt, 0.0, 2.0)
        check_range(f"{prefix}.gravity", self.gravity, 0.0, 100.0, lo_open=True, unit="m/s^2")
        warnings = []
        if not 0.2 <= self.belt_speed <= 2.5:
            warnings.append(
                f"{prefix}.belt_speed={self.belt_speed:g} m/s is outside the paper's range (4) "
                "[0.2, 2.5] m/s: the model was not validated there"
            )
        return warnings


@dataclass(frozen=True)
class ParcelParams:
    """The load: rectangle A (along the belt) x B (across), mass m_p, C_s offset (x_p, y_p).

    ``lateral_gap`` is Delta_s, the gap between the load and the fence-side border (y0 = 0).
    """

    length_a: float = 0.4  # A [m]
    width_b: float = 0.3  # B [m]
    height: float = 0.3  # [m], kinematics do not use it; kept for messages and visuals
    mass: float = 15.0  # m_p [kg]
    cog_offset_x: float = 0.0  # x_p [m], along A from the geometric centre
    cog_offset_y: float = 0.0  # y_p [m], along B from the geometric centre
    lateral_gap: float = 0.0  # Delta_s [m]
    yaw: float = 0.0  # phi [rad]

    def validate(self, prefix: str = "parcel", belt_width: float | None = None) -> None:
        check_range(f"{prefix}.length_a", self.length_a, 0.005, 3.0, unit="m")
        check_range(f"{prefix}.width_b", self.width_b, 0.005, 3.0, unit="m")
        check_range(f"{prefix}.height", self.height, 0.005, 3.0, unit="m")
        check_range(f"{prefix}.mass", self.mass, 0.01, 500.0, unit="kg")
        check_range(
            f"{prefix}.cog_offset_x", abs(self.cog_offset_x), 0.0, 0.5 * self.length_a, unit="m"
        )
        check_range(
            f"{prefix}.cog_offset_y", abs(self.cog_offset_y), 0.0, 0.5 * self.width_b, unit="m"
        )
        check_range(f"{prefix}.lateral_gap", self.lateral_gap, 0.0, 5.0, unit="m")
        check_range(f"{prefix}.yaw", self.yaw, -math.pi / 2, math.pi / 2, unit="rad")
        if belt_width is not None and self.lateral_gap + self.footprint_width() > belt_width:
            raise ParameterError(
                f"{prefix}: lateral_gap + footprint width "
                f"({self.lateral_gap:g} + {self.footprint_width():.3g} m) exceeds the belt width "
                f"{belt_width:g} m; {prefix}.lateral_gap must be in "
                f"[0, {max(belt_width - self.footprint_width(), 0.0):.3g}] m"
            )

    def footprint_width(self) -> float:
        """Extent across the belt of the yawed rectangle."""
        c, s = abs(math.cos(self.yaw)), abs(math.sin(self.yaw))
        return self.length_a * s + self.width_b * c


@dataclass(frozen=True)
class DriveParams:
    """Sinusoidal-velocity fence drive: swing to alpha_k in t1, return in t2 = t1.

    The drive starts (t = 0) when the load front is at x0 = R_s (``r_s``, paper range (3)).
    """

    alpha_k: float = math.radians(40.0)  # [rad]
    t1: float = 0.5  # working time [s], paper range (5): 0.1-1.5
    r_s: float = 0.0  # R_s [m]

    def validate(self, prefix: str = "drive") -> None:
        check_range(f"{prefix}.alpha_k", self.alpha_k, 0.0, math.radians(90.0), lo_open=True)
        check_range(f"{prefix}.t1", self.t1, 0.02, 10.0, unit="s")
        check_range(f"{prefix}.r_s", self.r_s, -5.0, 5.0, unit="m")


@dataclass(frozen=True)
class ContactParams:
    """Modified nonlinear Kelvin contact (16) and fence/border friction (37)."""

    b_p: float = 3.3e5  # damping factor [N s kg^-0.4 m^-3]
    k_p: float = 1.72e9  # stiffness factor [N m^-4]
    mu_fence: float = 0.35  # mu2, load against fence and against the border wall
    v_min: float = 1e-6  # Karnopp threshold [m/s] (34)-(37)
    phidot_min: float = 1e-6  # Karnopp threshold [rad/s] (36)
    deep_penetration: float = 0.5  # D beyond this share of min(A, B) is a diverged solve

    def validate(self, prefix: str = "contact") -> None:
        check_range(f"{prefix}.b_p", self.b_p, 0.0, 1e12)
        check_range(f"{prefix}.k_p", self.k_p, 0.0, 1e16, lo_open=True)
        check_range(f"{prefix}.mu_fence", self.mu_fence, 0.0, 2.0)
        check_range(f"{prefix}.v_min", self.v_min, 1e-12, 1.0, unit="m/s")
        check_range(f"{prefix}.phidot_min", self.phidot_min, 1e-12, 1.0, unit="rad/s")
        check_range(f"{prefix}.deep_penetration", self.deep_penetration, 0.01, 1.0)


@dataclass(frozen=True)
class SolverParams:
    """Time integration: method, steps or tolerances, end conditions (see ``stepper``).

    ``method``: ``adaptive`` (default; error-controlled trapezoidal), ``trapezoidal`` or
    ``generalized_alpha`` (fixed step ``dt``), or a SciPy baseline ``scipy:RK45``,
    ``scipy:DOP853``, ``scipy:Radau``, ``scipy:BDF``, ``scipy:LSODA`` (``rtol``/``atol``), or a
    compiled peer (CyRK) ``cyrk:LSODA``, ``cyrk:BDF``, ``cyrk:Radau``, ``cyrk:RK45``,
    ``cyrk:DOP853``, ``cyrk:Tsit5`` (``rtol``/``atol``).
    """

    method: str = "adaptive"
    dt: float = 5e-4  # [s] fixed step (trapezoidal, generalized_alpha); first step (adaptive)
    dt_max: float = 5e-3  # [s] largest adaptive step
    rtol: float = 1e-4  # relative local-error tolerance (adaptive, scipy:*, cyrk:*)
    atol: float = 1e-6  # absolute local-error tolerance [m, m/s, rad] (adaptive, scipy:*, cyrk:*)
    rho_inf: float = 0.8  # generalized_alpha spectral radius at h -> infinity (1: no damping)
    max_iterations: int = 12
    tolerance: float = 1e-9  # fixed-point tolerance on positions [m] and velocities [m/s]
    min_dt: float = 1e-7  # step halving stops here and the solve is reported as failed
    t_end: float = 0.0  # [s]; 0 = until sorted or the fence cycle (2 t1) ends plus settle
    settle_time: float = 0.5  # [s] after the cycle for a load that is still moving
    stop_when_sorted: bool = True
    max_wall_time: float = 120.0  # [s]; a solve that takes longer is stopped and reported

    def validate(self, prefix: str = "solver") -> None:
        if self.method not in SOLVER_METHODS:
            raise ParameterError(
                f"{prefix}.method must be one of {', '.join(SOLVER_METHODS)}, got {self.method!r}"
            )
        check_range(f"{prefix}.dt", self.dt, 1e-7, 0.01, unit="s")
        check_range(f"{prefix}.dt_max", self.dt_max, 1e-6, 0.05, unit="s")
        check_range(f"{prefix}.rtol", self.rtol, 1e-13, 0.1)
        check_range(f"{prefix}.atol", self.atol, 1e-15, 0.1)
        check_range(f"{prefix}.rho_inf", self.rho_inf, 0.0, 1.0)
        check_range(f"{prefix}.max_iterations", self.max_iterations, 1, 200)
        check_range(f"{prefix}.tolerance", self.tolerance, 1e-15, 1e-2)
        check_range(f"{prefix}.min_dt", self.min_dt, 1e-12, self.dt)
        check_range(f"{prefix}.t_end", self.t_end, 0.0, 600.0, unit="s")
        check_range(f"{prefix}.settle_time", self.settle_time, 0.0, 60.0, unit="s")
        check_range(f"{prefix}.max_wall_time", self.max_wall_time, 0.1, 3600.0, unit="s")


OUR_METHODS = ("adaptive", "trapezoidal", "generalized_alpha")
SCIPY_METHODS = ("scipy:RK45", "scipy:DOP853", "scipy:Radau", "scipy:BDF", "scipy:LSODA")
# compiled peers: CyRK's C++ solvers on the same compiled right-hand side (``peers``)
CYRK_METHODS = ("cyrk:LSODA", "cyrk:BDF", "cyrk:Radau", "cyrk:RK45", "cyrk:DOP853", "cyrk:Tsit5")
SOLVER_METHODS = OUR_METHODS + SCIPY_METHODS + CYRK_METHODS


def field_names(cls) -> tuple[str, ...]:
    """Names of a dataclass's fields (used by the scene loader to reject unknown keys)."""
    return tuple(f.name for f in fields(cls))


PROFILES = ("constant_strength", "uniform")
MAX_ELEMENTS = 200


@dataclass(frozen=True)
class FenceParams:
    """Geometry, material (PA6) and discretisation of the flexible fence (section 4.3)."""

    length: float = 1.2  # R_z [m]
    height: float = 0.1  # z [m]
    root_thickness: float = 0.08  # h1 [m]
    profile: str = "constant_strength"  # h(s) = h1 sqrt(1 - s / R_z), or "uniform": h = h1
    youngs_modulus: float = 3.0e9  # E [Pa]
    poisson_ratio: float = 0.39  # nu [-]; only for the reported shear modulus
    density: float = 1140.0  # rho_b [kg/m^3]
    elements: int = 10  # n_E
    damping_ratio: float = 0.05  # zeta on modes 1 and 2 (Rayleigh)

    @property
    def shear_modulus(self) -> float:
        """G = E / (2 (1 + nu)) [Pa]; reported only, Euler-Bernoulli ignores shear."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    def validate(self) -> None:
        """Raise ValueError naming the first field outside its allowed range."""
        # (field, low, high, low inclusive, high inclusive, unit)
        ranges = (
            ("length", 0.0, 10.0, False, True, "m"),
            ("height", 0.0, 1.0, False, True, "m"),
            ("root_thickness", 0.0, 1.0, False, True, "m"),
            ("youngs_modulus", 0.0, 1.0e12, False, True, "Pa"),
            ("poisson_ratio", -1.0, 0.5, False, False, ""),
            ("density", 0.0, 1.0e5, False, True, "kg/m^3"),
            ("damping_ratio", 0.0, 1.0, True, False, ""),
        )
        for name, lo, hi, lo_in, hi_in, unit in ranges:
            value = getattr(self, name)
            span = f"{'[' if lo_in else '('}{lo:g}, {hi:g}{']' if hi_in else ')'}"
            ok = (
                isinstance(value, (int, float))
                and not isinstance(value, bool)
                and math.isfinite(value)
                and (value >= lo if lo_in else value > lo)
                and (value <= hi if hi_in else value < hi)
            )
            if not ok:
                unit_txt = f" {unit}" if unit else ""
                raise ValueError(
                    f"fence.{name} must be a finite number in {span}{unit_txt}, got {value!r}"
                )
        n = self.elements
        if (
            isinstance(n, bool)
            or not isinstance(n, numbers.Integral)
            or not 1 <= n <= MAX_ELEMENTS
        ):
            raise ValueError(
                f"fence.elements must be an integer in [1, {MAX_ELEMENTS}], got {n!r}"
            )
        if self.profile not in PROFILES:
            raise ValueError(f"fence.profile must be one of {PROFILES}, got {self.profile!r}")
