"""Capacity and constraints of section 3 (ROS-free): W_t (1), Delta_c (2), (7)-(12) margins,
one stroke evaluated on the twin, and the controller's planner (reused by the optimiser)."""

from fence_sorter.capacity.constraints import CONSTRAINT_IDS, ConstraintProfile, margins
from fence_sorter.capacity.evaluate import StrokeEvaluation, evaluate_stroke, planning_scenario
from fence_sorter.capacity.formulas import capacity, pitch, scraping_time, stroke_capacity
from fence_sorter.capacity.planner import LoadRequest, Plan, Planner, PlannerConfig

__all__ = [
    "CONSTRAINT_IDS",
    "ConstraintProfile",
    "LoadRequest",
    "Plan",
    "Planner",
    "PlannerConfig",
    "StrokeEvaluation",
    "capacity",
    "evaluate_stroke",
    "margins",
    "pitch",
    "planning_scenario",
    "scraping_time",
    "stroke_capacity",
]
