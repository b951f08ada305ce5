"""Every parcel's replays for a list of parameter sets, run in parallel on the evaluation pool
(:func:`fence_sorter.pool.evaluation_pool`): forked processes that hold the parcels from their
start, the same driven by Dask's multiprocessing scheduler, or a Dask cluster."""

from __future__ import annotations

import contextlib
import os
from dataclasses import replace

from fence_sorter.physics.simulate import Scenario
from fence_sorter.pool import evaluation_pool

from .events import CalibrationInputError, EventData, FitError, predict
from .replay import ReplayError, replay

_WORKER: dict = {}


def _init_worker(base: Scenario, eds: list[EventData]) -> None:
    _WORKER["base"], _WORKER["eds"] = base, eds


def _predict_all(base: Scenario, eds: list[EventData], idx, values_list):
    """Predictions of parcels ``idx`` of ``eds`` for each parameter set, or the message of the
    first replay that failed."""
    out = []
    for values in values_list:
        row = []
        for i in idx:
            try:
                row.append(predict(base, eds[i], values))
            except ReplayError as exc:
                return str(exc)
        out.append(row)
    return out


def _predict_strokes(base: Scenario, eds: list[EventData], idx, values, widths):
    """Per parcel of ``idx``, its predictions with each stroke parameter (STROKE_FIELDS) moved
    by + and - its width (``widths`` by parcel id; six: start +-, alpha_k +-, t1 +-), or the
    message of the first replay that failed. A later start samples the same replay earlier."""
    out = []
    for i in idx:
        ed = eds[i]
        dt0, dak, dt1 = widths[ed.ev.parcel_id]
        try:
            tr = replay(base, ed.ev, values)
            row = []
            for d in (dt0, -dt0):
                row.append((*tr.pose_at(ed.cam_tau - d), tr.moment_at(ed.str_tau - d)))
            for name, w in (("alpha_k", dak), ("t1", dt1)):
                for d in (w, -w):
                    ev = replace(ed.ev, **{name: getattr(ed.ev, name) + d})
                    row.append(predict(base, replace(ed, ev=ev), values))
        except ReplayError as exc:
            return str(exc)
        out.append(row)
    return out


def _run_chunk(task, idx: list[int], *args):
    """``task`` (:func:`_predict_all`, :func:`_predict_strokes`) on the parcels this worker
    process holds (:func:`_init_worker`)."""
    return task(_WORKER["base"], _WORKER["eds"], idx, *args)


def _run_detached(task, base: Scenario, eds: list[EventData], *args):
    """``task`` on every parcel of ``eds``, for a worker that holds none (a Dask cluster's)."""
    return task(base, eds, range(len(eds)), *args)


#: how parcels' replays are run in parallel: ``processes`` (a pool of forked processes),
#: ``dask`` (the same processes driven by Dask's multiprocessing scheduler) or the address of
#: a Dask distributed scheduler (tcp://host:8786)
SCHEDULERS = ("processes", "dask")


def check_scheduler(scheduler: str) -> str:
    """``scheduler`` if it is one of SCHEDULERS or a Dask scheduler address, else
    CalibrationInputError naming the allowed values."""
    if scheduler in SCHEDULERS or "://" in scheduler:
        return scheduler
    raise CalibrationInputError(
        f"--scheduler {scheduler}: allowed: {', '.join(SCHEDULERS)} or a Dask scheduler "
        "address such as tcp://127.0.0.1:8786"
    )


class Evaluator:
    """Replays every parcel for a list of parameter sets, parcels split over processes.

    A call replays each parcel once per parameter set (a Jacobian's sets in one batch); the
    parcels are split into interleaved chunks, one task per chunk, run by ``scheduler``
    (:data:`SCHEDULERS`) on ``workers`` processes that hold the parcels from their start."""

    def __init__(
        self,
        base: Scenario,
        eds: list[EventData],
        workers: int | None = None,
        scheduler: str = "processes",
    ):
        self.base, self.eds = base, eds
        self.scheduler = check_scheduler(scheduler)
        self.workers = max(1, min(workers or os.cpu_count() or 1, len(eds)))
        self.pool = None
        self._stack = contextlib.ExitStack()
        if "://" in scheduler:
            self.pool = self._stack.enter_context(evaluation_pool(scheduler, workers))
        elif self.workers > 1:
            self.pool = self._stack.enter_context(
                evaluation_pool(
                    None,
                    self.workers,
                    # compile (or load) the kernel once here, so the forked workers inherit it
                    warm_up=lambda: replay(base, eds[0].ev),
                    initializer=_init_worker,
                    initargs=(base, eds),
                )
            )
        else:
            _init_worker(base, eds)
        n = len(eds)
        k = min(n, 2 * self.workers) if self.workers > 1 or "://" in scheduler else 1
        self.chunks = [list(range(i, n, k)) for i in range(k)]
        self.replays = 0
        self.on_replays = None  # callback(count) for a progress bar

    def close(self) -> None:
        """Shut the processes down (and wait for them, so their CPU time is counted)."""
        self._stack.close()
        self.pool = None

    def _parts(self, task, *args) -> list:
        """``task``'s result per chunk of parcels (``args`` after the chunk's indices)."""
        if "://" in self.scheduler:
            futures = [
                self.pool.submit(_run_detached, task, self.base, [self.eds[i] for i in c], *args)
                for c in self.chunks
            ]
            return [f.result() for f in futures]
        if self.scheduler == "dask":
            import dask  # lazy: Dask (0.2-1.6 s), only to evaluate in parallel

            tasks = [dask.delayed(_run_chunk, pure=False)(task, c, *args) for c in self.chunks]
            if self.pool is None:
                return list(dask.compute(*tasks, scheduler="synchronous"))
            return list(dask.compute(*tasks, scheduler="processes", pool=self.pool))
        if self.pool is None:
            return [_run_chunk(task, c, *args) for c in self.chunks]
        futures = [self.pool.submit(_run_chunk, task, c, *args) for c in self.chunks]
        return [f.result() for f in futures]

    def _gather(self, parts, rows: int) -> list:
        """Per row of the chunks' results, the list over every parcel; FitError on a failure."""
        out = [[None] * len(self.eds) for _ in range(rows)]
        for chunk, part in zip(self.chunks, parts, strict=True):
            if isinstance(part, str):
                raise FitError(part)
            for j, row in enumerate(part):
                for i, pred in zip(chunk, row, strict=True):
                    out[j][i] = pred
        return out

    def _count(self, replays: int) -> None:
        self.replays += replays
        if self.on_replays is not None:
            self.on_replays(replays)

    def __call__(self, values_list: list[dict[str, float]]):
        """Per parameter set, the list (per event) of predictions."""
        out = self._gather(self._parts(_predict_all, values_list), len(values_list))
        self._count(len(values_list) * len(self.eds))
        return out

    def strokes(self, values: dict[str, float], widths) -> list:
        """Per parcel, its six predictions of :func:`_predict_strokes` (``widths``: per parcel,
        the steps of its start, alpha_k and t1)."""
        by_id = {ed.ev.parcel_id: tuple(w) for ed, w in zip(self.eds, widths, strict=True)}
        parts = self._parts(_predict_strokes, values, by_id)
        (out,) = self._gather([p if isinstance(p, str) else [p] for p in parts], 1)
        self._count(5 * len(self.eds))
        return out
        return out
