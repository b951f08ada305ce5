"""Process figures of section 3: scraping time t_z, pitch Delta_c (2) and capacity W_t (1).

Plain functions of floats, shared by the controller's planner and the capacity optimiser.
"""

from __future__ import annotations

import math

from fence_sorter.physics.params import ParameterError, check_range


def cycle_time(t1: float) -> float:
    """t_c = t1 + t2 with t2 = t1 (return motion mirrors the working motion) [s]."""
    return 2.0 * t1


def scraping_time(v: float, t1: float, r_s: float) -> float:
    """t_z = t_c + |R_s| / v, the time of load scraping (section 3, below (2)) [s]."""
    check_range("v", v, 0.0, math.inf, lo_open=True, unit="m/s")
    return cycle_time(t1) + abs(r_s) / v


def pitch(v: float, t1: float, r_s: float, a_max: float, gap: float) -> float:
    """Delta_c (2): distance between load fronts [m].

    Delta_c = v t_z if v t_z > A_max + Delta, else A_max + Delta (Delta: gap between loads).
    """
    check_range("a_max", a_max, 0.0, math.inf, lo_open=True, unit="m")
    check_range("gap", gap, 0.0, math.inf, unit="m")
    vt_z = v * scraping_time(v, t1, r_s)
    return vt_z if vt_z > a_max + gap else a_max + gap


def capacity(v: float, delta_c: float) -> float:
    """W_t = 3600 v / Delta_c (1) [pcs/h]."""
    if not (math.isfinite(delta_c) and delta_c > 0.0):
        raise ParameterError(f"delta_c must be in (0, inf) m, got {delta_c!r}")
    return 3600.0 * v / delta_c


def stroke_capacity(v: float, t1: float, r_s: float, a_max: float, gap: float) -> float:
    """W_t (1) of a stroke (R_s, t1) at belt speed v with Delta_c from (2) [pcs/h]."""
    return capacity(v, pitch(v, t1, r_s, a_max, gap))
