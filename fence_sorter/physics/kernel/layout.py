"""Layout of the kernel's flat arrays: packed parameters ``P_*`` (:func:`pack`), contact slot
columns ``C_*``, resultants ``R_*``."""

from __future__ import annotations

from collections import namedtuple

import numpy as np

# -- packed parameters --------------------------------------------------------------------------
P_ALPHA_K = 0  # alpha_k [rad]
P_T1 = 1  # t1 [s]
P_MASS = 2  # m_p [kg]
P_INERTIA = 3  # I_p about C_s [kg m^2]
P_FMAX = 4  # mu1 m g [N]
P_TMAX = 5  # pure-spin torque [N m]
P_BEFF = 6  # b_p m_p^0.4
P_KP = 7  # k_p [N/m^4]
P_MU2 = 8  # fence / border friction
P_VMIN = 9  # Karnopp threshold [m/s]
P_PHIDOT_MIN = 10  # [rad/s]
P_LENGTH = 11  # R_z [m]
P_DL = 12  # element length [m] (flexible)
P_NEL = 13  # elements (flexible)
P_USE_BORDER = 14
P_USE_TIP = 15
P_FLEX = 16
P_BELT = 17  # belt speed [m/s]
P_EXT_X = 18  # external wrench on the load
P_EXT_Y = 19
P_EXT_M = 20
P_MARGIN = 21  # cheap-reject margin beyond the deflection [m]
N_PARAMS = 22

# -- contact slot columns -----------------------------------------------------------------------
C_ACTIVE = 0  # 1: force acting (D > 0)
C_GAP = 1  # 1: a fence candidate whose D and Ddot are known (for onset/release location)
C_S = 2  # arc position [m]
C_D = 3  # D [m]
C_DDOT = 4  # Ddot [m/s]
C_N = 5  # N [N] (clipped >= 0)
C_NRAW = 6  # the law (16) before the clip (negative: adhesion the clip removes)
C_FT = 7  # tangential friction force on the load [N]
C_PX = 8  # contact point
C_PY = 9
C_NX = 10  # unit normal of the force on the load
C_NY = 11
C_VSX = 12  # surface velocity at the contact point (0 for the border)
C_VSY = 13
N_COLS = 14
N_SLOTS = 12
SLOT_TIP = 4
SLOT_BORDER = 8

# -- results ------------------------------------------------------------------------------------
R_FX = 0  # contact resultant plus external wrench on the load (belt friction excluded)
R_FY = 1
R_MZ = 2
R_FENCE_N = 3  # sum of N over fence contacts [N]
R_MAX_D = 4  # deepest D [m]
R_POWER_FENCE = 5  # power of the fence contact forces at the fence surface velocity [W]
R_ALPHA = 6  # alpha_w [rad]
R_RATE = 7
R_ACCEL = 8
R_TIP_W = 9  # tip deflection [m]
R_MAX_W = 10  # largest nodal |w| [m]
R_ENERGY_CONTACT = 11  # potential of the k_p D^4 springs, sum k D^5 / 5 [J]
R_ACTIVE_MASK = 12  # bit k set: slot k carries a force
R_ITERATIONS = 13  # contact iterations the step that produced this point took
N_RES = 14


def pack(
    *,
    alpha_k,
    t1,
    mass,
    inertia,
    f_max,
    t_max,
    b_p,
    k_p,
    mu2,
    v_min,
    phidot_min,
    length,
    dl,
    n_el,
    use_border,
    use_tip,
    flexible,
    belt,
    external,
    margin=0.05,
) -> np.ndarray:
    """The packed parameter vector ``P`` (SI units)."""
    # filled as a list, one array at the end (a NumPy item assignment per field costs ~1 us on
    # a cold cache; a model is built per event)
    p = [0.0] * N_PARAMS
    p[P_ALPHA_K], p[P_T1] = alpha_k, t1
    p[P_MASS], p[P_INERTIA], p[P_FMAX], p[P_TMAX] = mass, inertia, f_max, t_max
    p[P_BEFF], p[P_KP], p[P_MU2] = b_p * mass**0.4, k_p, mu2
    p[P_VMIN], p[P_PHIDOT_MIN] = v_min, phidot_min
    p[P_LENGTH], p[P_DL], p[P_NEL] = length, dl, n_el
    p[P_USE_BORDER], p[P_USE_TIP], p[P_FLEX] = float(use_border), float(use_tip), float(flexible)
    p[P_BELT] = belt
    p[P_EXT_X], p[P_EXT_Y], p[P_EXT_M] = external
    p[P_MARGIN] = margin
    return np.array(p, dtype=float)


# The loop's arrays in two groups, as MuJoCo's MjModel and MjData: what one event is (read only)
# and what the loop writes as it runs (rows of accepted and trial states, counters, outputs).
LoopModel = namedtuple(
    "LoopModel",
    [
        "params",  # packed parameters P_* (layout.pack)
        "corners",  # the load's corners relative to C_s [m]
        "normals",  # the load's face normals
        "phi",  # modal shapes at the fence nodes (flexible; else empty)
        "rigid_modal",  # modal load of a unit drive acceleration
        "omega",  # modal angular frequencies [rad/s]
        "zeta",  # modal damping ratios
        "settings",  # solver settings G_*
        "breaks",  # drive breakpoints and the end time [s]
    ],
)
LoopState = namedtuple(
    "LoopState",
    [
        "counters",  # integer state of the loop I_* (rows in use, steps, events, diagnosis)
        "scalars",  # float state of the loop F_* (step sizes, history, peaks, energy audit)
        "times",  # t of the state rows S_* [s]
        "states",  # state vectors of the rows
        "belt_wrench",  # belt friction (F_x, F_y, M_z) of the rows
        "contacts",  # contact slots C_* of the rows
        "resultants",  # resultants R_* of the rows
        "modal_force",  # modal force of the rows
        "accelerations",  # accelerations of the rows
        "deflection",  # nodal deflection and slope of the fence (scratch)
        "deflection_rate",
        "nodes",
        "friction_prev",  # each slot's friction at the previous contact iterate
        "work",  # the trapezoidal step's workspace
        "propagator_keys",  # cache of the modal propagators per step size
        "propagators",
        "propagator_g0",
        "propagator_g1",
        "impacts",  # rows (t, w_n, N_stiff)
        "stages",  # rows (t, stage code)
        "record",  # recorded series REC_*, a column per accepted point
    ],
)
