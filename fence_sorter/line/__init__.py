"""The sorting line with many parcels at once, ROS-free (the simulator node's model).

See :class:`SortingLine`; data types in :mod:`fence_sorter.line.types`, input checks in
:mod:`fence_sorter.inputs`. Nothing here imports rclpy.
"""

from fence_sorter.codes import StartMode
from fence_sorter.inputs import (
    PARCEL_REASONS,
    InputError,
    ParcelSpec,
    StrokeCommand,
    validate_command,
    validate_parcel,
)

from .line import LineConfig, SortingLine, in_swept_sector
from .pacing import LatenessHistogram, Pacer, Tick
from .types import (
    CommandResult,
    EventTrace,
    FenceSnapshot,
    LineEvent,
    LineSnapshot,
    Outcome,
    OutcomeCode,
    OverlapWarning,
    ParcelSnapshot,
    SolverWarning,
    Stage,
    StrokeStarted,
)

__all__ = [
    "PARCEL_REASONS",
    "CommandResult",
    "EventTrace",
    "FenceSnapshot",
    "InputError",
    "LatenessHistogram",
    "LineConfig",
    "LineEvent",
    "LineSnapshot",
    "Outcome",
    "OutcomeCode",
    "OverlapWarning",
    "ParcelSnapshot",
    "Pacer",
    "ParcelSpec",
    "SolverWarning",
    "SortingLine",
    "Stage",
    "StartMode",
    "StrokeCommand",
    "StrokeStarted",
    "Tick",
    "in_swept_sector",
    "validate_command",
    "validate_parcel",
]
