"""The evaluation pool of the optimiser and the sweeps: :func:`fence_sorter.pool.evaluation_pool`
with the optimiser's warm-up (local processes, or a Dask cluster)."""

from __future__ import annotations

import concurrent.futures
import math
from contextlib import AbstractContextManager

from fence_sorter import pool
from fence_sorter.optimize.problem import OptimizeSpec
from fence_sorter.optimize.solve import evaluate_point


def evaluation_pool(
    scheduler: str | None = None, workers: int | None = None
) -> AbstractContextManager[concurrent.futures.Executor]:
    """:func:`fence_sorter.pool.evaluation_pool` whose local processes are forked once this
    process has compiled the kernel and read the scenes of an optimisation."""
    return pool.evaluation_pool(scheduler, workers, warm_up=_warm_up)


def _warm_up() -> None:
    """Compile (or load) the kernel and read the scenes in this process before forking."""
    spec = OptimizeSpec(case="positioned", alpha_k=math.radians(40.0), constraints=(8,))
    evaluate_point(spec, {"R_s": 0.7, "v": 2.0, "t1": 0.5, "R_z": 1.2})
