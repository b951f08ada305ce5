"""Capacity and constraints of section 3 (ROS-free): W_t (1), Delta_c (2), (7)-(12) margins,
one stroke evaluated on the twin, and the controller's planner (reused by the optimiser).

The names below are loaded on first use (PEP 562): importing ``capacity.constraints`` (every
node's parameters do) must not import the physics and Numba through ``evaluate`` and
``planner``, ~1 s of a node process's start that the scanner and the recorder never use.
"""

from fence_sorter.lazy import lazy_names

__getattr__, __all__ = lazy_names(
    __name__,
    {
        ".constraints": ("CONSTRAINT_IDS", "ConstraintProfile", "margins"),
        ".evaluate": ("StrokeEvaluation", "evaluate_stroke", "planning_scenario"),
        ".formulas": ("capacity", "pitch", "scraping_time", "stroke_capacity"),
        ".planner": ("LoadRequest", "Plan", "Planner", "PlannerConfig"),
    },
)
