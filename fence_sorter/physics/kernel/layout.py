"""Layout of the kernel's arrays: the named records of one event's parameters (:data:`PARAMS`,
:func:`pack`) and solver settings (:data:`SETTINGS`) and of the loop's counters
(:data:`COUNTERS`) and float state (:data:`FIGURES`); an evaluation's contact slots
(:data:`CONTACT`) and resultants (:data:`RESULT`), a recorded point (:data:`RECORDED`), and the
solve loop's arrays (:data:`LoopModel`, :data:`LoopState`) and their named rows (:data:`Row`,
:data:`Rows`), diagnoses ``DIAG_*``.

A record travels as an array of one element (``params[0].mass``, ``counters[0].n_steps``):
Numba compiles a field of it to the same load or store at a fixed offset as an index into a
flat array (the same machine code, compared with ``inspect_asm``), and the loop's arguments
stay arrays, which the ahead-of-time entry (``aot``) exports. Numba's structref and
named tuples were not taken: a structref is reference counted (the kernel runs without
Numba's reference counting) and a named tuple cannot be written in place.

The state rows are named, not numbered: the arrays of a :data:`LoopState` that hold one row
per state (times, states, accelerations, belt wrenches, contact slots, resultants, modal
forces; their widths are the model's: n states, m modes) have :data:`N_ROWS` rows, and
``loop.loop_rows`` hands the loop one :data:`Row` of views per row (no copies), bundled as
:data:`Rows`: the two trial rows that alternate (``rows.trial[counters[0].cur]`` is the
accepted point, ``rows.trial[counters[0].trial]`` the step being tried), ``located``,
``before``, ``alpha`` and ``previous``. The rows' order in the arrays is the fields' order of
:data:`Rows`, the trial pair first, and only ``loop_rows`` relies on it."""

from __future__ import annotations

from collections import namedtuple

import numpy as np


def _record(fields) -> np.dtype:
    """A record dtype of named fields (NumPy's ``np.record``, so an element of an array of it
    has attribute access ``r.mass`` under NUMBA_DISABLE_JIT as under Numba). Every field is
    8 bytes wide, so the aligned layout has no padding."""
    return np.dtype((np.record, np.dtype(fields, align=True)))


# -- parameters of one event (read only) ----------------------------------------------------
PARAMS = _record(
    [
        ("alpha_k", "f8"),  # [rad]
        ("t1", "f8"),  # [s]
        ("mass", "f8"),  # m_p [kg]
        ("inertia", "f8"),  # I_p about C_s [kg m^2]
        ("f_max", "f8"),  # mu1 m g [N]
        ("t_max", "f8"),  # pure-spin torque [N m]
        ("b_eff", "f8"),  # b_p m_p^0.4
        ("k_p", "f8"),  # [N/m^4]
        ("mu2", "f8"),  # fence / border friction
        ("v_min", "f8"),  # Karnopp threshold [m/s]
        ("phidot_min", "f8"),  # [rad/s]
        ("length", "f8"),  # R_z [m]
        ("dl", "f8"),  # element length [m] (flexible)
        ("n_el", "f8"),  # elements (flexible)
        ("use_border", "f8"),  # 1.0: the border wall is a contact
        ("use_tip", "f8"),  # 1.0: the fence tip is a contact
        ("flexible", "f8"),  # 1.0: a flexible fence
        ("belt", "f8"),  # belt speed [m/s]
        ("ext_x", "f8"),  # external wrench on the load [N, N, N m]
        ("ext_y", "f8"),
        ("ext_m", "f8"),
        ("margin", "f8"),  # cheap-reject margin beyond the deflection [m]
        ("deep", "f8"),  # deep-penetration depth [m]: deeper off the fence is round the tip
    ]
)


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
    deep=np.inf,
) -> np.ndarray:
    """The parameters of one event: an array of one :data:`PARAMS` record (SI units)."""
    # one tuple, one array (a NumPy field assignment each costs ~1 us on a cold cache; a model
    # is built per event)
    row = (
        alpha_k, t1, mass, inertia, f_max, t_max, b_p * mass**0.4, k_p, mu2, v_min, phidot_min,
        length, dl, n_el, float(use_border), float(use_tip), float(flexible), belt, *external,
        margin, deep,
    )  # fmt: skip
    return np.array([row], dtype=PARAMS)


# -- contact slots ------------------------------------------------------------------------------
# a slot of the contact array (``out[k].d``; an evaluation's slots are an array of N_SLOTS)
CONTACT = _record(
    [
        ("active", "f8"),  # 1: force acting (D > 0)
        ("gap", "f8"),  # 1: a fence candidate whose D and Ddot are known (onset/release location)
        ("s", "f8"),  # arc position [m]
        ("d", "f8"),  # D [m]
        ("ddot", "f8"),  # Ddot [m/s]
        ("n", "f8"),  # N [N] (clipped >= 0)
        ("n_raw", "f8"),  # the law (16) before the clip (negative: adhesion the clip removes)
        ("ft", "f8"),  # tangential friction force on the load [N]
        ("px", "f8"),  # contact point
        ("py", "f8"),
        ("nx", "f8"),  # unit normal of the force on the load
        ("ny", "f8"),
        ("vsx", "f8"),  # surface velocity at the contact point (0 for the border)
        ("vsy", "f8"),
        (
            "slack",
            "f8",
        ),  # fence friction: mu N - |the implicit stick force| (> 0 sticks; nan explicit)
        (
            "fmean",
            "f8",
        ),  # the step's mean friction (impulse / h) of a contact sticking at the step end
    ]
)
N_SLOTS = 12
SLOT_TIP = 4
SLOT_BORDER = 8

# -- results ------------------------------------------------------------------------------------
# the resultants of one evaluation (an array of one record, ``res[0].fx``)
RESULT = _record(
    [
        (
            "fx",
            "f8",
        ),  # contact resultant plus external wrench on the load (belt friction excluded)
        ("fy", "f8"),
        ("mz", "f8"),
        ("fence_n", "f8"),  # sum of N over fence contacts [N]
        ("max_d", "f8"),  # deepest D [m]
        (
            "power_fence",
            "f8",
        ),  # power of the fence contact forces at the fence surface velocity [W]
        ("alpha", "f8"),  # alpha_w [rad]
        ("rate", "f8"),
        ("accel", "f8"),
        ("tip_w", "f8"),  # tip deflection [m]
        ("max_w", "f8"),  # largest nodal |w| [m]
        ("energy_contact", "f8"),  # potential of the k_p D^4 springs, sum k D^5 / 5 [J]
        ("active_mask", "f8"),  # bit k set: slot k carries a force
        ("iterations", "f8"),  # contact iterations the step that produced this point took
    ]
)


def zero_slots() -> np.ndarray:
    """Zeroed contact slots of one evaluation (an array of N_SLOTS :data:`CONTACT` records)."""
    return np.zeros(N_SLOTS, CONTACT)


def zero_result() -> np.ndarray:
    """Zeroed resultants of one evaluation (an array of one :data:`RESULT` record)."""
    return np.zeros(1, RESULT)


# -- the solve loop's arrays ---------------------------------------------------------------
# One state row of the loop: views of row i of the LoopState arrays that have a row per state
# (``loop.loop_rows`` builds them once per solve call)
Row = namedtuple(
    "Row",
    [
        "time",  # t [s]: a view of one element (``row.time[0]``)
        "state",  # the state vector (n)
        "acceleration",  # accelerations (3 + m)
        "belt",  # belt friction (F_x, F_y, M_z)
        "contacts",  # N_SLOTS CONTACT records
        "resultant",  # one RESULT record
        "modal",  # modal force (m)
    ],
)
# The loop's state rows by role
Rows = namedtuple(
    "Rows",
    [
        "trial",  # the two rows that alternate: counters[0].cur (accepted) and .trial (tried)
        "located",  # the trial step of an event location
        "before",  # the last located step that ended before a slide-off
        "alpha",  # the generalized-alpha step's state at its alpha point (scratch)
        "previous",  # the accepted point before cur (its modal force: the modes' quadratic force)
    ],
)
N_ROWS = 6  # rows of each such array: trial[0], trial[1], located, before, alpha, previous

# the solver settings of one event (read only)
SETTINGS = _record(
    [
        ("h_nom", "f8"),  # dt_max (adaptive) or dt (fixed step) [s]
        ("t_end", "f8"),  # [s]
        ("dt", "f8"),  # first adaptive step [s]
        ("min_dt", "f8"),  # [s]
        ("tol", "f8"),  # contact iteration tolerance
        ("max_iter", "f8"),
        ("atol", "f8"),
        ("rtol", "f8"),
        ("v_ref", "f8"),  # [m/s]
        ("om_ref", "f8"),  # [rad/s]
        ("width", "f8"),  # s [m]
        ("adaptive", "f8"),  # 1.0: the adaptive scheme
        ("stop_sorted", "f8"),  # 1.0: stop once sorted
        ("record", "f8"),  # 1.0: record the series
        ("b_p", "f8"),  # b_p, k_p of the stiff reference (stiff_impact_peak)
        ("k_p", "f8"),
        ("deep", "f8"),  # the divergence checks' depth [m] and speed [m/s]
        ("speed_limit", "f8"),
        ("v_min", "f8"),  # [m/s]
        ("phidot_min", "f8"),  # [rad/s]
        ("up", "f8"),  # 2^(1/4)
        ("down", "f8"),  # 2^(-1/4)
        ("flush", "f8"),  # observer.FLUSH_ANGLE [rad]
        ("gen_alpha", "f8"),  # 1.0: the generalized-alpha step (fixed step), 0: trapezoidal
        ("alpha_coefficients", "f8", (4,)),  # generalized-alpha (alpha_m, alpha_f, beta, gamma)
    ]
)

# the integer state of the loop
COUNTERS = _record(
    [
        ("cur", "i8"),  # which of rows.trial holds the accepted point, which the trial
        ("trial", "i8"),
        ("started", "i8"),
        ("done", "i8"),
        ("diag", "i8"),  # DIAG_*
        ("n_steps", "i8"),
        ("n_rejected", "i8"),
        ("n_forced", "i8"),
        ("n_events", "i8"),
        ("next_break", "i8"),
        ("clean", "i8"),
        ("on_belt", "i8"),
        ("stop", "i8"),
        ("sorted", "i8"),  # the reductions (observe)
        ("touched", "i8"),
        ("had_fence", "i8"),
        ("first", "i8"),
        ("mask", "i8"),
        ("stage", "i8"),
        ("last_mask0", "i8"),
        ("last_mask1", "i8"),
        ("n_impacts", "i8"),
        ("n_stages", "i8"),
        ("n_rec", "i8"),
        ("n_props", "i8"),  # entries of the propagator cache in use
    ]
)

# the float state of the loop
FIGURES = _record(
    [
        ("h", "f8"),
        ("h_cap", "f8"),
        ("h_prev", "f8"),
        ("prev_v", "f8", (3,)),
        ("prev_a", "f8", (3,)),
        ("exit_speed", "f8"),  # the reductions (observe)
        ("impact_speed", "f8"),
        ("peak_n", "f8"),
        ("peak_tip", "f8"),
        ("max_depth", "f8"),
        ("y_max", "f8"),
        ("prev_t", "f8"),
        ("prev_y", "f8", (6,)),
        ("prev_power", "f8"),
        ("work", "f8"),
        ("last_n1", "f8"),
        ("last_n2", "f8"),
        ("last_t1", "f8"),
        ("last_t2", "f8"),
        ("max_res", "f8"),  # energy audit (result.EnergyAudit)
        ("min_res", "f8"),
        ("flow", "f8"),
        ("e0", "f8"),
        ("t_max", "f8"),
        ("t_min", "f8"),
        ("max_rise", "f8"),
        ("t_rise0", "f8"),
        ("t_rise1", "f8"),
        ("run_min", "f8"),
        ("t_run_min", "f8"),
        ("diag_t", "f8"),  # where a diagnosis was made, and its value (D or speed)
        ("diag_v", "f8"),
    ]
)

# diagnoses (counters.diag)
DIAG_NONE = 0
DIAG_NONFINITE = 1
DIAG_DEEP = 2
DIAG_SPEED = 3
DIAG_MIN_DT = 4

# the fields of a recorded point: (field, the recordable group of ``scenario.RECORDABLE`` it
# belongs to, the names of its series, one per element). Each group has its own time field
# (the time again), so each recorded series is a field of its own; the stepper's series
# follow this order within a group
RECORDED_SERIES = (
    ("t", "trajectory", ("t",)),
    ("y", "trajectory", ("x", "y", "phi", "vx", "vy", "phidot")),
    ("t_fence", "fence", ("t_fence",)),
    ("alpha", "fence", ("alpha_w",)),
    ("tip_w", "fence", ("tip_deflection",)),
    ("t_forces", "forces", ("t_forces",)),
    ("fence_n", "forces", ("normal_force",)),
    ("max_d", "forces", ("deformation",)),
    ("t_stage", "stages", ("t_stage",)),
    ("stage", "stages", ("stage",)),
)
# a recorded point (the loop's ``record`` is an array of them, one per accepted point)
RECORDED = _record(
    [(f, "f8", (len(names),)) if len(names) > 1 else (f, "f8") for f, _, names in RECORDED_SERIES]
)
N_PROP_CACHE = 256

# What the forces and the right-hand side read of one event (``forces.evaluate``, ``rhs.rhs``
# take it, or a LoopModel, which begins with the same fields)
ForceModel = namedtuple(
    "ForceModel",
    [
        "params",  # one PARAMS record (layout.pack)
        "corners",  # the load's corners relative to C_s [m]
        "normals",  # the load's face normals
        "mode_shapes",  # modal shapes at the fence nodes (flexible; else empty)
        "rigid_modal",  # modal load of a unit drive acceleration
        "omega",  # modal angular frequencies [rad/s]
        "zeta",  # modal damping ratios
    ],
)
# What one evaluation of the forces writes (``forces.evaluate``): its contact slots, resultants
# and modal force, the fence's shape (scratch), each slot's friction at the previous contact
# iterate, and the belt wrench (``rhs.rhs`` writes it; a step reads the start's)
Evaluation = namedtuple(
    "Evaluation",
    [
        "contacts",  # N_SLOTS CONTACT records
        "resultant",  # one RESULT record
        "modal",  # modal force (m)
        "deflection",  # nodal deflection and slope of the fence
        "deflection_rate",
        "nodes",  # chord chain node positions
        "friction_prev",  # N_SLOTS
        "belt",  # belt wrench (F_x, F_y, M_z)
    ],
)

# The loop's arrays in two groups, as MuJoCo's MjModel and MjData: what one event is (read only)
# and what the loop writes as it runs (rows of accepted and trial states, counters, outputs).
LoopModel = namedtuple(
    "LoopModel",
    [
        *ForceModel._fields,
        "settings",  # one SETTINGS record
        "breakpoints",  # drive breakpoints and the end time [s]
    ],
)
LoopState = namedtuple(
    "LoopState",
    [
        "counters",  # one COUNTERS record: rows in use, steps, events, diagnosis
        "figures",  # one FIGURES record: step sizes, history, peaks, energy audit
        "times",  # t of the state rows (N_ROWS, named by Rows) [s]
        "states",  # state vectors of the rows
        "belt_wrench",  # belt friction (F_x, F_y, M_z) of the rows
        "contacts",  # contact slots (CONTACT) of the rows
        "resultants",  # resultants (one RESULT) of the rows
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
        "record",  # recorded points (RECORDED), one per accepted point
    ],
)


#: the names of the layout, re-exported by the package (``from .layout import *``)
__all__ = [
    n
    for n in tuple(globals())
    if n.isupper()
    or n
    in (
        "ForceModel",
        "Evaluation",
        "LoopModel",
        "LoopState",
        "Row",
        "Rows",
        "pack",
        "zero_slots",
        "zero_result",
    )
]
