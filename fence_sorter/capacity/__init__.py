"""Capacity and constraints of section 3 (ROS-free): W_t (1), Delta_c (2), (7)-(12) margins,
one stroke evaluated on the twin, and the controller's planner (reused by the optimiser).

The names below are loaded on first use (PEP 562): importing ``capacity.constraints`` (every
node's parameters do) must not import the physics and Numba through ``evaluate`` and
``planner``, ~1 s of a node process's start that the scanner and the recorder never use.
"""

from importlib import import_module

_WHERE = {
    "CONSTRAINT_IDS": "constraints",
    "ConstraintProfile": "constraints",
    "margins": "constraints",
    "StrokeEvaluation": "evaluate",
    "evaluate_stroke": "evaluate",
    "planning_scenario": "evaluate",
    "capacity": "formulas",
    "pitch": "formulas",
    "scraping_time": "formulas",
    "stroke_capacity": "formulas",
    "LoadRequest": "planner",
    "Plan": "planner",
    "Planner": "planner",
    "PlannerConfig": "planner",
}
__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    globals()[name] = value
    return value
