"""The capacity optimisation problem of section 3: max W_t (1) over X = [R_s, v, t1, R_z].

:class:`OptimizeSpec` states one problem (case, alpha_k, limits of (10)-(12), the constraints
that count, friction, the limiting load, variables held fixed, range overrides, fence model).
It also knows the loads the twin is run on for each X (:meth:`OptimizeSpec.loads`):

* ``positioned`` (section 4.2): the limiting load A x B of mass m_p at the fence-side border
  (Delta_s = 0);
* ``arbitrary`` (section 4.1): the same limiting load at Delta_s = 0 and the minimal object
  (length ``min_length`` along the belt, 0.1 m wide, 1 kg) on the far side (Delta_s = s - 0.1 m,
  the T_g case of (9)); A_max of (2) is the longer of the two;

each with both limiting centre-of-gravity positions of Fig. 2 (rear and front corner on the fence
side); the worse margin of every constraint counts.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from fence_sorter.capacity.constraints import CONSTRAINT_IDS, ConstraintProfile
from fence_sorter.physics.params import ParameterError, ParcelParams, check_range

#: decision variables X of (1), in this order
VARIABLES = ("R_s", "v", "t1", "R_z")
#: ranges (3)-(6) of the paper [m, m/s, s, m]
PAPER_RANGES: dict[str, tuple[float, float]] = {
    "R_s": (-0.5, 2.0),
    "v": (0.2, 2.5),
    "t1": (0.1, 1.5),
    "R_z": (0.2, 2.5),
}
#: what the twin accepts at all (range overrides must lie within; fixed values within the
#: ranges)
HARD_LIMITS: dict[str, tuple[float, float]] = {
    "R_s": (-5.0, 5.0),
    "v": (0.05, 10.0),
    "t1": (0.02, 10.0),
    "R_z": (0.05, 10.0),
}
UNITS = {"R_s": "m", "v": "m/s", "t1": "s", "R_z": "m"}
CASES = ("arbitrary", "positioned")
FENCES = ("stiff", "flexible")
#: belt width s [m] (the scenes' conveyor; (8) measures y_k against it)
BELT_WIDTH = 0.7
#: what belt widths s the problem accepts [m]
BELT_WIDTH_RANGE = (0.2, 5.0)
#: the minimal object of section 4.1: 0.1 x 0.1 m at Delta_s = s - 0.1 m (0.6 m on s = 0.7 m)
MINIMAL_SIZE = 0.1
#: the shortest minimal object along the belt [m]
MIN_LENGTH_LOW = 0.05
#: masses of the limiting and the minimal load [kg] (those of the positioned_stiff and
#: arbitrary_stiff scenes; the paper does not state them, a stiff drive makes a_N = N / m_p
#: nearly independent of m_p)
LIMITING_MASS = 5.0
MINIMAL_MASS = 1.0
#: what masses of the limiting load the problem accepts [kg] (ParcelParams' range)
MASS_RANGE = (0.01, 500.0)
LOAD_HEIGHT = 0.1


@dataclass(frozen=True)
class OptimizeSpec:
    """One optimisation problem; SI units (alpha_k in rad)."""

    case: str  # "arbitrary" | "positioned"
    alpha_k: float  # [rad]
    w_dop: float = 2.4  # (10) limit [m/s]
    a_ndop: float = 300.0  # (11) limit [m/s^2]
    exit_speed_limit: float = 2.5  # ydot_dop of (12) [m/s]
    constraints: tuple[int, ...] = (7, 8, 9, 10)  # which of (7)-(12) count
    mu1: float = 0.65  # load-belt friction
    mu2: float = 0.35  # load-fence friction
    load_length: float = 0.7  # A of the limiting load [m]
    load_width: float = 0.1  # B [m]
    fixed: tuple[tuple[str, float], ...] = ()  # variables held fixed, e.g. (("R_s", 0.0),)
    bounds: tuple[tuple[str, float, float], ...] = ()  # overrides of ranges (3)-(6)
    fence: str = "stiff"  # "stiff" | "flexible"
    seed: int = 0
    budget: int = 4000  # max twin evaluations (points X simulated) per restart
    restarts: int = 3  # independent searches (seeds seed, seed + 1, ...); the best counts
    gap: float = 0.0  # Delta of (2): least distance between loads [m]
    mass: float = LIMITING_MASS  # m_p of the limiting load [kg]
    belt_width: float = BELT_WIDTH  # s of (8) [m]
    min_length: float = MINIMAL_SIZE  # length along the belt of the minimal object [m]

    # -- validation ------------------------------------------------------------------------
    def validate(self) -> OptimizeSpec:
        """Raise ParameterError naming the field and its allowed range; return self."""
        if self.case not in CASES:
            raise ParameterError(f"case must be one of {', '.join(CASES)}, got {self.case!r}")
        if self.fence not in FENCES:
            raise ParameterError(f"fence must be one of {', '.join(FENCES)}, got {self.fence!r}")
        check_range("alpha_k", self.alpha_k, 0.0, math.radians(89.0), lo_open=True, unit="rad")
        check_range("w_dop", self.w_dop, 0.0, 100.0, lo_open=True, unit="m/s")
        check_range("a_ndop", self.a_ndop, 0.0, 1e5, lo_open=True, unit="m/s^2")
        check_range(
            "exit_speed_limit", self.exit_speed_limit, 0.0, 100.0, lo_open=True, unit="m/s"
        )
        check_range("mu1", self.mu1, 0.0, 2.0)
        check_range("mu2", self.mu2, 0.0, 2.0)
        check_range("load_length", self.load_length, 0.05, 3.0, unit="m")
        check_range("belt_width", self.belt_width, *BELT_WIDTH_RANGE, unit="m")
        check_range("load_width", self.load_width, 0.05, self.belt_width, unit="m")
        # the minimal object is no longer than the limiting load (nor than 0.1 m when A < 0.1 m)
        longest = max(self.load_length, MINIMAL_SIZE)
        check_range("min_length", self.min_length, MIN_LENGTH_LOW, longest, unit="m")
        check_range("mass", self.mass, *MASS_RANGE, unit="kg")
        check_range("gap", self.gap, 0.0, 10.0, unit="m")
        cons = tuple(self.constraints)
        if (
            not cons
            or len(set(cons)) != len(cons)
            or not all(isinstance(c, int) and c in CONSTRAINT_IDS for c in cons)
        ):
            raise ParameterError(
                f"constraints must be distinct numbers from {list(CONSTRAINT_IDS)} (at least "
                f"one), got {list(cons)}"
            )
        for name, field in (
            ("seed", self.seed),
            ("budget", self.budget),
            ("restarts", self.restarts),
        ):
            if isinstance(field, bool) or not isinstance(field, int):
                raise ParameterError(f"{name} must be an integer, got {field!r}")
        check_range("seed", self.seed, 0, 2**32 - 1)
        check_range("budget", self.budget, 1, 10**7)
        check_range("restarts", self.restarts, 1, 100)
        seen: set[str] = set()
        for item in self.bounds:
            if len(item) != 3:
                raise ParameterError(f"bounds entries are (name, low, high), got {item!r}")
            name, lo, hi = item
            self._check_name("bounds", name, seen)
            hl, hh = HARD_LIMITS[name]
            check_range(f"bounds.{name} low", lo, hl, hh, unit=UNITS[name])
            check_range(f"bounds.{name} high", hi, hl, hh, unit=UNITS[name])
            if lo > hi:
                raise ParameterError(
                    f"bounds.{name}: low {lo:g} exceeds high {hi:g} {UNITS[name]}; the range "
                    f"must be [low, high] within [{hl:g}, {hh:g}] {UNITS[name]}"
                )
        seen = set()
        for item in self.fixed:
            if len(item) != 2:
                raise ParameterError(f"fixed entries are (name, value), got {item!r}")
            name, value = item
            self._check_name("fixed", name, seen)
            lo, hi = self.ranges()[name]
            if not (isinstance(value, int | float) and lo <= value <= hi):
                raise ParameterError(
                    f"fixed.{name} must be in [{lo:g}, {hi:g}] {UNITS[name]} (its search "
                    f"range), got {value!r}"
                )
        return self

    @staticmethod
    def _check_name(what: str, name, seen: set[str]) -> None:
        if name not in VARIABLES:
            raise ParameterError(
                f"{what}: unknown variable {name!r}; allowed: {', '.join(VARIABLES)}"
            )
        if name in seen:
            raise ParameterError(f"{what}: {name} is given twice")
        seen.add(name)

    # -- derived ----------------------------------------------------------------------------
    def ranges(self) -> dict[str, tuple[float, float]]:
        """Ranges (3)-(6) with the overrides of ``bounds`` applied."""
        out = dict(PAPER_RANGES)
        for name, lo, hi in self.bounds:
            out[name] = (float(lo), float(hi))
        return out

    def fixed_values(self) -> dict[str, float]:
        return {name: float(value) for name, value in self.fixed}

    def free_variables(self) -> tuple[str, ...]:
        fixed = self.fixed_values()
        return tuple(n for n in VARIABLES if n not in fixed)

    def profile(self) -> ConstraintProfile:
        """The constraint profile of (7)-(12) handed to ``evaluate_stroke``."""
        return ConstraintProfile(
            w_dop=self.w_dop,
            a_ndop=self.a_ndop,
            ydot_dop=self.exit_speed_limit,
            active=tuple(self.constraints),
        )

    def loads(self) -> tuple[tuple[str, ParcelParams], ...]:
        """(name, load) pairs the twin runs for each X: both C_s positions of Fig. 2 of the
        limiting load at Delta_s = 0, and (case ``arbitrary``) of the minimal object at
        Delta_s = s - 0.1 m. C_s on a corner on the fence side (y offset -B/2), rear or front."""
        out = []
        sets = [("limiting", self.load_length, self.load_width, 0.0, self.mass)]
        if self.case == "arbitrary":
            far = self.belt_width - MINIMAL_SIZE
            sets.append(("minimal", self.min_length, MINIMAL_SIZE, far, MINIMAL_MASS))
        for name, a, b, gap, mass in sets:
            for cog, sign in (("rear", -1.0), ("front", 1.0)):
                parcel = ParcelParams(
                    length_a=a,
                    width_b=b,
                    height=LOAD_HEIGHT,
                    mass=mass,
                    cog_offset_x=sign * 0.5 * a,
                    cog_offset_y=-0.5 * b,
                    lateral_gap=gap,
                )
                out.append((f"{name}_{cog}", parcel))
        return tuple(out)

    def a_max(self) -> float:
        """A_max of (2): the longest load of the case [m]."""
        return (
            max(self.load_length, self.min_length)
            if self.case == "arbitrary"
            else self.load_length
        )

    def to_dict(self) -> dict:
        d = asdict(self)
        d["alpha_k_deg"] = math.degrees(self.alpha_k)
        d["constraints"] = list(self.constraints)
        d["fixed"] = {n: v for n, v in self.fixed}
        d["bounds"] = {n: [lo, hi] for n, lo, hi in self.bounds}
        return d
