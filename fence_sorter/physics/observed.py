"""The stepper interface of a general-purpose solver observed by the solve loop's reductions.

``ScipyStepper`` (:mod:`fence_sorter.physics.baselines`) and ``CyrkStepper``
(:mod:`fence_sorter.physics.peers`) integrate the compiled ``kernel.rhs`` with a solver that is
not ours and feed its accepted points to a :class:`~fence_sorter.physics.stepper.Stepper` that
integrates nothing (:attr:`ObservedStepper.reduce`): its reductions (peaks, impacts, stages,
sorting, energy audit, recorded series) and divergence checks answer for them, so both families
step and report exactly as ``stepper.SolveStepper`` does. This class is what they share: the
state, the interface's read-only views, the end and failure bookkeeping and the result.
Subclasses implement :meth:`step` (one accepted point, reduced) and may override
:meth:`advance`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from .stepper import Diagnosis, Failure, Stepper, segments


class ObservedStepper:
    """One sorting event stepped by another solver, reduced by the solve loop's reductions.

    End time and breakpoints are ``stepper.segments``; ``status`` is running, finished or
    failed (``diagnosis`` says why); ``steps`` counts the accepted steps."""

    def __init__(self, model, clock: Callable[[], float] = time.perf_counter):
        self.wall0 = clock()
        self.clock = clock
        self.model = model
        self.t_end, self.breakpoints = segments(model.sc)
        # the reductions and divergence checks of the solve loop, fed the accepted points
        self.reduce = Stepper(model, clock)
        self.steps = 0
        self.status = "running"
        self.diagnosis: Diagnosis | None = None
        self._k_break = 0
        self._t = 0.0
        self._y = np.array(model.initial_state(), dtype=np.float64)
        self.on_belt = True
        self._stop = False  # the reductions' stop (sorted)

    # -- the stepper interface ---------------------------------------------------------------

    @property
    def t(self) -> float:
        return self._t

    @property
    def y(self) -> np.ndarray:
        return self._y

    @property
    def running(self) -> bool:
        return self.status == "running"

    @property
    def resultants(self) -> np.ndarray:
        return self.reduce.resultants

    @property
    def contacts(self) -> np.ndarray:
        return self.reduce.contacts

    @property
    def stage(self):
        return self.reduce.stage

    @property
    def sorted(self) -> bool:
        return self.reduce.sorted

    @property
    def impacts(self) -> list[tuple[float, float, float]]:
        return self.reduce.impacts

    def start(self) -> None:
        """Nothing to do: the initial point is reduced on construction."""

    def step(self) -> str | None:
        """One accepted step, reduced; None, or the diagnosis text when the solve failed."""
        raise NotImplementedError

    def advance(self, t_target: float = math.inf) -> bool:
        """Step until the accepted time reaches ``t_target`` (or the end); False once the
        solve has ended."""
        while self.status == "running":
            if self._t >= t_target:
                return True
            self.step()
        return False

    def result(
        self, *, steps: int | None = None, diagnosis: str | None = None, wall: float | None = None
    ):
        """The :class:`SimulationResult` from the loop's reductions of the accepted points."""
        if diagnosis is None and self.diagnosis is not None:
            diagnosis = self.diagnosis.text
        return self.reduce.result(
            steps=self.steps if steps is None else steps,
            diagnosis=diagnosis,
            wall=self.clock() - self.wall0 if wall is None else wall,
        )

    def release(self) -> None:
        """Hand the reductions' arrays back for the next solve (after :meth:`result`)."""
        self.reduce.release()

    # -- internals -----------------------------------------------------------------------------

    def _check_end(self) -> None:
        if self.status == "running" and (self._stop or not self._t < self.t_end - 1e-12):
            self.status = "finished"

    def _fail(self, kind: Failure, t: float, value: float, text: str) -> None:
        self.diagnosis = Diagnosis(kind, t, value, text)
        self.status = "failed"


__all__ = ["ObservedStepper"]
