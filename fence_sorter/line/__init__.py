"""The sorting line with many parcels at once, ROS-free (the simulator node's model).

See :class:`SortingLine`; data types in :mod:`fence_sorter.line.types`, input checks in
:mod:`fence_sorter.inputs`. Nothing here imports rclpy.

The names below are loaded on first use (PEP 562): ``line.types`` is imported by every node
(``nodes.convert``) and must not import the line's physics, the kernel and Numba through
``line.line``, ~1 s of the start of a node process that does not simulate.
"""

from fence_sorter.lazy import lazy_names

__getattr__, __all__ = lazy_names(
    __name__,
    {
        "fence_sorter.codes": ("StartMode",),
        "fence_sorter.inputs": (
            "PARCEL_REASONS",
            "InputError",
            "ParcelSpec",
            "StrokeCommand",
            "validate_command",
            "validate_parcel",
        ),
        ".line": ("LineConfig", "SortingLine", "in_swept_sector"),
        ".pacing": ("LatenessHistogram", "Pacer", "Tick"),
        ".types": (
            "CommandResult",
            "EventTrace",
            "FenceSnapshot",
            "LineEvent",
            "LineSnapshot",
            "Outcome",
            "OutcomeCode",
            "OverlapWarning",
            "ParcelSnapshot",
            "SolverWarning",
            "Stage",
            "StrokeStarted",
        ),
    },
)
