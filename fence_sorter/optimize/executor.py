"""The executor the optimiser evaluates the twin on: local processes, or a Dask cluster.

Both are ``concurrent.futures.Executor``s; the optimiser only calls ``submit`` and
``Future.result``, so the code path is the same.
"""

from __future__ import annotations

import concurrent.futures
import math
import multiprocessing
import os
from collections.abc import Iterator
from contextlib import contextmanager

from fence_sorter.optimize.problem import OptimizeSpec
from fence_sorter.optimize.solve import evaluate_point
from fence_sorter.physics.params import ParameterError


@contextmanager
def evaluation_pool(
    scheduler: str | None = None, workers: int | None = None
) -> Iterator[concurrent.futures.Executor]:
    """A process pool of ``workers`` (default: the CPU count) processes, or, with a scheduler
    address ("tcp://host:8786"), the executor of a dask.distributed Client connected to it.
    The pool or the client is shut down on exit."""
    if workers is not None and (isinstance(workers, bool) or not 1 <= int(workers) <= 1024):
        raise ParameterError(f"workers must be in [1, 1024], got {workers!r}")
    if scheduler is None:
        # fork: the workers inherit the imported, JIT-compiled physics (spawn would re-import
        # and each worker would compile the kernel anew when Numba's cache is stale)
        _warm_up()
        ctx = multiprocessing.get_context("fork")
        pool = concurrent.futures.ProcessPoolExecutor(workers or os.cpu_count() or 1, ctx)
        try:
            yield pool
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        return
    if not isinstance(scheduler, str) or "://" not in scheduler:
        raise ParameterError(
            f"scheduler must be a Dask scheduler address such as tcp://127.0.0.1:8786, "
            f"got {scheduler!r}"
        )
    try:  # optional: only a --scheduler run needs dask, and it takes seconds to import
        from dask.distributed import Client  # lazy: Dask (0.2-1.6 s), only to evaluate in parallel
    except ImportError as exc:  # pragma: no cover - dask is a listed requirement
        raise ParameterError(f"scheduler needs dask[distributed] installed: {exc}") from None
    try:
        client = Client(scheduler, timeout="10s")
    except OSError as exc:
        raise ParameterError(f"scheduler {scheduler}: cannot connect ({exc})") from None
    try:
        yield client.get_executor()
    finally:
        client.close()


def _warm_up() -> None:
    """Compile (or load) the kernel and read the scenes in this process before forking."""
    spec = OptimizeSpec(case="positioned", alpha_k=math.radians(40.0), constraints=(8,))
    evaluate_point(spec, {"R_s": 0.7, "v": 2.0, "t1": 0.5, "R_z": 1.2})
