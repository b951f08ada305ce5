"""The sorting line, ROS-free: one fence with many parcels at once (the simulator node's
model, :mod:`fence_sorter.line.one_fence`) and a line of several fence units
(:mod:`fence_sorter.line.multi_unit`, from a line file, :mod:`fence_sorter.line.line_file`).

See :class:`SortingLine`; data types in :mod:`fence_sorter.line.types`, input checks in
:mod:`fence_sorter.inputs`. Nothing here imports rclpy.

The names below are loaded on first use (PEP 562): ``line.types`` is imported by every node
(``nodes.convert``) and must not import the line's physics, the kernel and Numba through
``line.one_fence``, ~1 s of the start of a node process that does not simulate.
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
        ".one_fence": ("LineConfig", "SortingLine"),
        ".sector": ("in_swept_sector",),
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
