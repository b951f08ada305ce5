"""Plain data of the sorting line: outcomes, snapshots (no ROS types); its inputs, parcels and
stroke commands, are :mod:`fence_sorter.inputs`.

Frame "sorter" is the paper's O x0 y0: origin on the fence rotation axis at the fence-side belt
border, x0 along the belt motion, y0 across the belt towards the chute (belt 0 <= y0 <= s).
SI units, angles in rad. The integer codes mirror fence_sorter_msgs (SortOutcome, LoadState,
FenceCommand) so the node layer converts them one to one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fence_sorter.codes import OutcomeCode, Stage

NAN = math.nan


@dataclass(frozen=True)
class CommandResult:
    """What the line did with a command: accepted, or rejected with a reason key and text.

    ``code`` is one of ``accepted``, ``infeasible`` (accepted as the controller's "no stroke"),
    ``unknown_parcel``, ``duplicate``, ``parcel_done``, ``not_divert``, ``invalid``, ``late``,
    ``fence_busy``, ``outside_window`` (the stroke would outlast its parcel on the line).
    """

    accepted: bool
    code: str
    reason: str
    start_time: float = NAN  # planned start of the working motion [s] (accepted strokes)


@dataclass(frozen=True)
class Outcome:
    """Outcome of one parcel (SortOutcome); figures NaN when the parcel met no stroke."""

    parcel_id: int
    t: float  # sim time of the outcome [s]
    code: OutcomeCode
    reason: str
    peak_normal_force: float = NAN  # N [N]
    peak_normal_force_stiff: float = NAN  # N_stiff [N]
    peak_normal_accel: float = NAN  # a_N [m/s^2]
    impact_normal_speed: float = NAN  # w_n [m/s]
    exit_speed_y: float = NAN  # ydot at y0 = s [m/s]
    y_max: float = NAN  # [m]
    time_in_working_space: float = NAN  # [s]

    @property
    def sorted(self) -> bool:
        return self.code is OutcomeCode.SORTED


@dataclass(frozen=True)
class OverlapWarning:
    """Another parcel lies in the fence's swept sector during a stroke (parcel-parcel and
    fence-bystander contact are not modelled): reported once per stroke and parcel."""

    t: float
    stroke_parcel_id: int
    other_parcel_id: int


@dataclass(frozen=True)
class StrokeStarted:
    """The fence started the working motion for a parcel (informational)."""

    t: float
    parcel_id: int
    r_s: float
    t1: float
    alpha_k: float


@dataclass(frozen=True)
class SolverWarning:
    """The solve of a stroke failed after its parcel already had its outcome (fence only)."""

    t: float
    parcel_id: int
    diagnosis: str


#: the columns of :attr:`EventTrace.steps`, in order
TRACE_COLUMNS = (
    "t", "stage", "contact_set", "normal_force", "deformation", "deformation_rate",
    "tip_deflection", "drive_angle", "x", "y", "yaw", "vx", "vy", "yaw_rate",
)  # fmt: skip


@dataclass(frozen=True)
class EventTrace:
    """One sorting event at the solver's resolution (SortEvent), sent with its parcel's outcome.

    ``steps``: one row per accepted step of the stroke's solve from the stroke start up to the
    outcome (a sorted parcel: the step where C_s crossed y0 = s), columns
    :data:`TRACE_COLUMNS` (t since the stroke start [s], LoadState stage, the contact set as
    bits, N [N], D [m], dD/dt [m/s], tip deflection [m], alpha_w [rad], C_s pose and velocity).
    ``impacts``: one row per impact, (onset since the stroke start [s], w_n [m/s], peak
    N_stiff [N]). ``b_p``, ``k_p``: contact law (16) of the stroke, for the N_stiff course.
    """

    parcel_id: int
    t: float  # sim time of the outcome [s]
    start_time: float  # sim time of the stroke start [s]
    mass: float  # m_p [kg]
    b_p: float
    k_p: float
    steps: np.ndarray  # (n, len(TRACE_COLUMNS))
    impacts: np.ndarray  # (k, 3)

    def column(self, name: str) -> np.ndarray:
        return self.steps[:, TRACE_COLUMNS.index(name)]


LineEvent = Outcome | OverlapWarning | StrokeStarted | SolverWarning | EventTrace


@dataclass(frozen=True)
class FenceSnapshot:
    """Drive angle and fence shape; arrays per beam node, root first (FenceState)."""

    drive_angle: float  # alpha_w [rad]
    drive_rate: float  # [rad/s]
    drive_accel: float  # [rad/s^2]
    node_s: np.ndarray  # arc position [m]
    node_x: np.ndarray  # [m], frame sorter
    node_y: np.ndarray
    deflection: np.ndarray  # transverse, relative to the rigid fence line [m]
    rotation: np.ndarray  # [rad]
    tip_deflection: float  # [m]
    stroke_parcel_id: int | None  # parcel of the running stroke, None at rest
    from_solve: bool  # False: rigid drive kinematics (stiff fence, at rest, or after a failure)


@dataclass(frozen=True)
class ParcelSnapshot:
    """One parcel on the line (LoadState): C_s pose and velocity, contact figures."""

    parcel_id: int
    stage: Stage
    x: float  # C_s [m]
    y: float
    yaw: float  # [rad]
    vx: float  # [m/s]
    vy: float
    yaw_rate: float  # [rad/s]
    contact_normal_force: float = 0.0  # N [N]
    contact_normal_force_stiff: float = 0.0  # peak N_stiff of the current impact [N]
    deformation: float = 0.0  # D [m]
    deformation_rate: float = 0.0  # dD/dt [m/s]
    contact_point: tuple[float, float] = (NAN, NAN)  # [m]
    length_a: float = 0.0
    width_b: float = 0.0
    height: float = 0.0
    corners: tuple[tuple[float, float], ...] = ()  # world corners [m]
    divert: bool = False


@dataclass(frozen=True)
class LineSnapshot:
    t: float
    fence: FenceSnapshot
    parcels: list[ParcelSnapshot] = field(default_factory=list)
