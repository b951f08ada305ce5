"""The one evaluation pool of the twin: local forked processes, or a Dask cluster.

The optimiser, the paper's sweeps and the calibration evaluate the twin on it. Both kinds are
``concurrent.futures.Executor``s; callers only ``submit`` and take ``Future.result``, so the
code path is the same on one machine and on a cluster.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from fence_sorter.physics.params import ParameterError

#: the most processes a pool may have
MAX_WORKERS = 1024


@contextmanager
def evaluation_pool(
    scheduler: str | None = None,
    workers: int | None = None,
    *,
    warm_up: Callable[[], object] | None = None,
    initializer: Callable[..., object] | None = None,
    initargs: tuple = (),
) -> Iterator[concurrent.futures.Executor]:
    """A pool of ``workers`` (default: the CPU count) forked processes, or, with a scheduler
    address ("tcp://host:8786"), the executor of a dask.distributed Client connected to it.
    The pool or the client is shut down on exit (and waited for, so the workers' CPU time is
    counted as this process's children's).

    Local processes only: ``warm_up`` runs here before the fork, so that the workers inherit
    the imported, JIT-compiled physics (spawn would re-import, and each worker would compile
    the kernel anew when Numba's cache is stale); ``initializer(*initargs)`` runs in each
    worker when it starts. A bad ``workers`` or ``scheduler`` is a ParameterError."""
    if workers is not None and (isinstance(workers, bool) or not 1 <= int(workers) <= MAX_WORKERS):
        raise ParameterError(f"workers must be in [1, {MAX_WORKERS}], got {workers!r}")
    if scheduler is None:
        if warm_up is not None:
            warm_up()
        pool = concurrent.futures.ProcessPoolExecutor(
            workers or os.cpu_count() or 1,
            multiprocessing.get_context("fork"),
            initializer=initializer,
            initargs=initargs,
        )
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
