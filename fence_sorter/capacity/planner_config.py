"""The planner's settings (:class:`PlannerConfig`): candidate grid, limits, model, budget,
load-class bins and the uncertainty set, from the controller's flat config keys."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from fence_sorter.capacity.constraints import ConstraintProfile
from fence_sorter.capacity.formulas import scraping_time
from fence_sorter.capacity.uncertainty import UncertaintySet
from fence_sorter.physics.params import ParameterError, check_range


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
    fence_model: str = "scene"  # "scene" (the plant's fence) or "stiff"
    max_evaluations: int = 60  # safety cap of twin evaluations per load (cached ones are free)
    deadline_margin: float = 0.02  # wall time kept before the command's deadline [s]
    # the least wall time a deadline gives (an unpaced simulator holds a parcel for its
    # command, so sim time over the real-time factor seen is not the time left there) [s]
    min_planning_time: float = 0.2
    uncertainty_mass: float = 0.05  # relative half-width of the load's mass
    uncertainty_mu: float = 0.05  # absolute half-width of mu1 and mu2
    uncertainty_size: float = 0.005  # half-width of A and B [m]
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
        "deadline_margin": (0.0, 10.0, "s"),
        "min_planning_time": (0.0, 10.0, "s"),
        "uncertainty_mass": (0.0, 0.5, ""),
        "uncertainty_mu": (0.0, 0.5, ""),
        "uncertainty_size": (0.0, 0.1, "m"),
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
        self.uncertainty.validate(prefix)
        return self

    @property
    def uncertainty(self) -> UncertaintySet:
        """The box around the scanned load a stroke is verified over."""
        return UncertaintySet(self.uncertainty_mass, self.uncertainty_mu, self.uncertainty_size)

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
