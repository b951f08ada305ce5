"""Capacity optimisation of sections 3-4 (ROS-free): max W_t (1) over X = [R_s, v, t1, R_z]
subject to (7)-(12) on the twin, for the arbitrary and positioned cases of section 4.

The names below are loaded on first use (PEP 562): ``fence-sorter optimize --help`` needs only
the light ``problem`` (the ranges and the defaults of :class:`OptimizeSpec`), not the physics
and Numba that ``solve`` brings.
"""

from fence_sorter.lazy import lazy_names

__getattr__, __all__ = lazy_names(
    __name__,
    {
        ".executor": ("evaluation_pool",),
        ".problem": ("PAPER_RANGES", "VARIABLES", "OptimizeSpec"),
        ".solve": ("OptimumResult", "evaluate_point", "grid_search", "optimize"),
    },
)
