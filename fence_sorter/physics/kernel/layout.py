"""Layout of the kernel's flat arrays: packed parameters ``P_*`` (:func:`pack`), contact slot
columns ``C_*``, resultants ``R_*``, and the solve loop's arrays (:data:`LoopModel`,
:data:`LoopState`): state rows ``S_*``, settings ``G_*``, counters ``I_*``, scalars ``F_*``,
diagnoses ``DIAG_*``, recorded rows ``REC_*``."""

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
C_SLACK = 14  # fence friction: mu N - |the implicit stick force| (> 0 sticks; nan explicit)
C_FMEAN = 15  # the step's mean friction (impulse / h) of a contact sticking at the step end
N_COLS = 16
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


# -- the solve loop's arrays ---------------------------------------------------------------
# state rows of times, states, belt_wrench, contacts, resultants, modal_forces, accelerations;
# cur and trial swap, loc and before are fixed; the generalized-alpha step's state at its
# alpha point goes in states[S_ALPHA] (scratch); modal_forces[S_PREV]: the modal force at
# the accepted point before cur (the modes' quadratic force)
S_LOC = 2
S_BEFORE = 3
S_ALPHA = 4
S_PREV = 5
N_STATES = 6

# the solver settings ``settings``
G_H_NOM = 0  # dt_max (adaptive) or dt (fixed step) [s]
G_T_END = 1
G_DT = 2  # first adaptive step [s]
G_MIN_DT = 3
G_TOL = 4  # contact iteration tolerance
G_MAX_ITER = 5
G_ATOL = 6
G_RTOL = 7
G_V_REF = 8
G_OM_REF = 9
G_WIDTH = 10  # s [m]
G_ADAPTIVE = 11
G_STOP_SORTED = 12
G_RECORD = 13
G_BP = 14  # b_p, k_p of the stiff reference (stiff_impact_peak)
G_KP = 15
G_DEEP = 16
G_SPEED_LIMIT = 17
G_VMIN = 18
G_PHIDOT_MIN = 19
G_UP = 20  # 2^(1/4)
G_DOWN = 21  # 2^(-1/4)
G_FLUSH = 22  # observer.FLUSH_ANGLE [rad]
G_GEN_ALPHA = 23  # 1: the generalized-alpha step (fixed step), 0: the trapezoidal one
G_ALPHA_M = 24  # generalized-alpha (alpha_m, alpha_f, beta, gamma), in this order
G_ALPHA_F = 25
G_BETA = 26
G_GAMMA = 27
N_CFG = 28

# the integer state of the loop ``counters``
I_CUR = 0
I_TRIAL = 1
I_STARTED = 2
I_DONE = 3
I_DIAG = 4  # DIAG_*
I_STEPS = 5
I_REJECTED = 6
I_FORCED = 7
I_EVENTS = 8
I_NEXT_BREAK = 9
I_CLEAN = 10
I_ON_BELT = 11
I_STOP = 12
I_SORTED = 13  # the reductions (observe)
I_TOUCHED = 14
I_HAD_FENCE = 15
I_FIRST = 16
I_MASK = 17
I_STAGE = 18
I_LAST_MASK0 = 19
I_LAST_MASK1 = 20
I_N_IMPACTS = 21
I_N_STAGES = 22
I_N_REC = 23
I_N_PROPS = 24  # entries of the propagator cache in use
N_CTL = 25

# the float state of the loop ``figures``
F_H = 0
F_H_CAP = 1
F_H_PREV = 2
F_PREV_V = 3  # 3 values
F_PREV_A = 6  # 3 values
F_EXIT_SPEED = 9  # the reductions (observe)
F_IMPACT_SPEED = 10
F_PEAK_N = 11
F_PEAK_TIP = 12
F_MAX_DEPTH = 13
F_Y_MAX = 14
F_PREV_T = 15
F_PREV_Y = 16  # 6 values
F_PREV_POWER = 22
F_WORK = 23
F_LAST_N1 = 24
F_LAST_N2 = 25
F_LAST_T1 = 26
F_LAST_T2 = 27
F_MAX_RES = 28  # energy audit (result.EnergyAudit)
F_MIN_RES = 29
F_FLOW = 30
F_E0 = 31
F_T_MAX = 32
F_T_MIN = 33
F_MAX_RISE = 34
F_T_RISE0 = 35
F_T_RISE1 = 36
F_RUN_MIN = 37
F_T_RUN_MIN = 38
F_DIAG_T = 39  # where a diagnosis was made, and its value (D or speed)
F_DIAG_V = 40
N_FC = 41

# diagnoses (counters[I_DIAG])
DIAG_NONE = 0
DIAG_NONFINITE = 1
DIAG_DEEP = 2
DIAG_SPEED = 3
DIAG_MIN_DT = 4

# rows of the recorded series
REC_T = 0
REC_Y = 1  # x, y, phi, vx, vy, phidot
REC_ALPHA = 7
REC_TIP_W = 8
REC_FENCE_N = 9
REC_MAX_D = 10
REC_STAGE = 11
# the time again, once per series group that has its own time array (fence, forces, stages), so
# each recorded array is a row of ``record`` of its own
REC_T_FENCE = 12
REC_T_FORCES = 13
REC_T_STAGE = 14
N_REC_COLS = 15
N_PROP_CACHE = 256

# The loop's arrays in two groups, as MuJoCo's MjModel and MjData: what one event is (read only)
# and what the loop writes as it runs (rows of accepted and trial states, counters, outputs).
LoopModel = namedtuple(
    "LoopModel",
    [
        "params",  # packed parameters P_* (layout.pack)
        "corners",  # the load's corners relative to C_s [m]
        "normals",  # the load's face normals
        "mode_shapes",  # modal shapes at the fence nodes (flexible; else empty)
        "rigid_modal",  # modal load of a unit drive acceleration
        "omega",  # modal angular frequencies [rad/s]
        "zeta",  # modal damping ratios
        "settings",  # solver settings G_*
        "breakpoints",  # drive breakpoints and the end time [s]
    ],
)
LoopState = namedtuple(
    "LoopState",
    [
        "counters",  # integer state of the loop I_* (rows in use, steps, events, diagnosis)
        "figures",  # float state of the loop F_* (step sizes, history, peaks, energy audit)
        "times",  # t of the state rows S_* [s]
        "states",  # state vectors of the rows
        "belt_wrench",  # belt friction (F_x, F_y, M_z) of the rows
        "contacts",  # contact slots C_* of the rows
        "resultants",  # resultants R_* of the rows
        "modal_forces",  # modal force of the rows
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
