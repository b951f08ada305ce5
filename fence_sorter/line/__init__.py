"""The sorting line with many parcels at once, ROS-free (the simulator node's model).

See :class:`SortingLine`; data types in :mod:`fence_sorter.line.types`, input checks in
:mod:`fence_sorter.inputs`. Nothing here imports rclpy.

The names below are loaded on first use (PEP 562): ``line.types`` is imported by every node
(``nodes.convert``) and must not import the line's physics, the kernel and Numba through
``line.line``, ~1 s of the start of a node process that does not simulate.
"""

from importlib import import_module

_WHERE = {
    "StartMode": "fence_sorter.codes",
    "PARCEL_REASONS": "fence_sorter.inputs",
    "InputError": "fence_sorter.inputs",
    "ParcelSpec": "fence_sorter.inputs",
    "StrokeCommand": "fence_sorter.inputs",
    "validate_command": "fence_sorter.inputs",
    "validate_parcel": "fence_sorter.inputs",
    "LineConfig": ".line",
    "SortingLine": ".line",
    "in_swept_sector": ".line",
    "LatenessHistogram": ".pacing",
    "Pacer": ".pacing",
    "Tick": ".pacing",
    "CommandResult": ".types",
    "EventTrace": ".types",
    "FenceSnapshot": ".types",
    "LineEvent": ".types",
    "LineSnapshot": ".types",
    "Outcome": ".types",
    "OutcomeCode": ".types",
    "OverlapWarning": ".types",
    "ParcelSnapshot": ".types",
    "SolverWarning": ".types",
    "Stage": ".types",
    "StrokeStarted": ".types",
}
__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(_WHERE[name], __name__), name)
    globals()[name] = value
    return value
