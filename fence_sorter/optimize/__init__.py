"""Capacity optimisation of sections 3-4 (ROS-free): max W_t (1) over X = [R_s, v, t1, R_z]
subject to (7)-(12) on the twin, for the arbitrary and positioned cases of section 4."""

from fence_sorter.optimize.executor import evaluation_pool
from fence_sorter.optimize.problem import PAPER_RANGES, VARIABLES, OptimizeSpec
from fence_sorter.optimize.solve import OptimumResult, evaluate_point, grid_search, optimize

__all__ = [
    "PAPER_RANGES",
    "VARIABLES",
    "OptimizeSpec",
    "OptimumResult",
    "evaluate_point",
    "grid_search",
    "evaluation_pool",
    "optimize",
]
