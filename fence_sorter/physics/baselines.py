"""SciPy ``OdeSolver`` baselines on the same right-hand side as our schemes.

``solver.method = scipy:<name>`` (RK45, DOP853, Radau, BDF, LSODA; ``params.SCIPY_METHODS``)
integrates the compiled right-hand side ``kernel.rhs`` (the same forces as the steppers, with
explicit Karnopp friction) with SciPy's ``OdeSolver`` class of that name, stepped one accepted
step at a time by :class:`ScipyStepper`, which has the interface of our schemes' ``Stepper``
(``stepper.SolveStepper``: ``simulate`` and the line step either), so the run is observed
exactly like ours: each accepted point goes through the solve loop's own reductions
(``Stepper.observe``, ``kernel.observe``: peaks, impacts, stages, sorting, energy audit,
recorded series) and its divergence checks (``kernel.diverged``).

What the baseline does and does not do, on purpose:

- ``rtol = solver.rtol``, ``atol = solver.atol`` on every state component (SciPy's norm; our
  ``adaptive`` controls the load's six only); ``max_step = solver.dt_max`` (the same cap as
  ``adaptive``); ``first_step`` SciPy's own choice.
- Implicit methods (Radau, BDF) and LSODA get their Jacobian by SciPy's finite differences.
- No event location: contact onset and release, the N >= 0 clamp and stick/slip switches fall
  inside steps and are handled by the error control alone; that is the baseline.
- The solver is restarted (fresh history, same tolerances) at the drive's breakpoints t1 and
  2 t1 (``stepper.segments``, where our schemes end steps too; the drive acceleration jumps at
  2 t1, and a segment starting there evaluates the right-hand side on its far side) and when
  the load crosses into the chute (belt friction off from then on).
- Stops: the observer's stop (sorted), the end time (``solver.t_end``, or 2 t1 plus
  ``solver.settle_time``), ``solver.max_wall_time``, a solver failure (SciPy's message) or a
  diverged state (``kernel.diverged``: NaN, deep penetration, runaway speed).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import scipy.integrate
from scipy.optimize import brentq

from . import kernel as K
from .observed import ObservedStepper
from .params import SCIPY_METHODS
from .stepper import Failure, Stepper, diagnosis_text


def solver_class(method: str):
    """The ``scipy.integrate`` OdeSolver class of ``scipy:<name>``."""
    if method not in SCIPY_METHODS:
        raise ValueError(f"not a SciPy baseline: {method!r}; one of {', '.join(SCIPY_METHODS)}")
    return getattr(scipy.integrate, method.split(":", 1)[1])


class RightHandSide:
    """``fun(t, y)`` over ``kernel.rhs`` with its own scratch arrays (trial points only)."""

    def __init__(self, model):
        md = model
        n = md.n_el
        self.model = md
        self.n = md.n_state
        self.arrays = K.ForceModel(
            md.P, md.corners, md.normals, md.phi, md.rigid_modal, md.omega, md.zeta
        )
        self.ev = K.Evaluation(
            K.zero_slots(), K.zero_result(), np.zeros(md.n_modes), np.zeros(max(2 * n, 2)),
            np.zeros(max(2 * n, 2)), np.zeros((n + 1, 2)), np.zeros(K.N_SLOTS), np.zeros(3),
        )  # fmt: skip
        self.on_belt = True
        self.after = -math.inf  # t at or below this is evaluated just past it (a segment start)

    def fill(self, t: float, y: np.ndarray, dy) -> None:
        """dy at (t, y); the forces, contacts and belt wrench there go to :attr:`ev`."""
        if t <= self.after:
            t = math.nextafter(self.after, math.inf)
        K.rhs(self.arrays, float(t), y, self.on_belt, dy, self.ev)

    def __call__(self, t, y):
        y = np.ascontiguousarray(y, dtype=np.float64)
        dy = np.empty(self.n)
        self.fill(t, y, dy)
        return dy

    def observe(self, stepper: Stepper, t: float, y: np.ndarray, on_belt: bool):
        """Reduce an accepted point (forces, contacts and belt wrench evaluated there) with the
        solve loop's reductions; ``(stop, on_belt)`` after it."""
        y = np.ascontiguousarray(y, dtype=np.float64)
        dy = np.empty(self.n)
        self.fill(float(t), y, dy)
        ev = self.ev
        return stepper.observe(float(t), y, ev.belt, ev.contacts, ev.resultant, on_belt)


def _edge_crossing(dense, t0: float, t1: float, width: float) -> tuple[float, np.ndarray]:
    """Time and state where C_s's y reaches ``width`` on the step's dense output."""
    t = float(brentq(lambda tt: dense(tt)[1] - width, t0, t1, xtol=1e-12))
    return t, np.array(dense(t), dtype=np.float64)


class ScipyStepper(ObservedStepper):
    """One sorting event integrated by a SciPy ``OdeSolver``, stepped as :class:`Stepper` steps
    our schemes (``stepper.SolveStepper``): :meth:`step` is one accepted SciPy step, observed by
    the solve loop's reductions (a :class:`Stepper` that integrates nothing, :attr:`reduce`),
    which also answer :attr:`resultants`, :attr:`contacts`, :attr:`stage`, :attr:`sorted`,
    :attr:`impacts` and :meth:`result`. End time and breakpoints are ``stepper.segments``."""

    def __init__(self, model, clock: Callable[[], float] = time.perf_counter):
        super().__init__(model, clock)
        self.cls = solver_class(model.sc.solver.method)
        self.fun = RightHandSide(model)
        self.solver = None  # the OdeSolver of the current segment (None: start one)
        self._stop, self.on_belt = self.fun.observe(self.reduce, 0.0, self._y, True)
        self._check_end()

    def step(self) -> str | None:
        """One accepted step of the SciPy solver (ended at the belt edge when C_s crosses it),
        reduced; None, or the diagnosis text when the solve failed. Raises once ended."""
        if self.status != "running":
            raise RuntimeError(f"step() on a {self.status} solve")
        sv = self.model.sc.solver
        fun = self.fun
        breaks = self.breakpoints
        t, y, on_belt = self._t, self._y, self.on_belt
        while breaks[self._k_break] <= t + 1e-12:
            self._k_break += 1
        if self.solver is None:
            fun.on_belt = on_belt
            self.solver = self.cls(
                fun, t, y, breaks[self._k_break], rtol=sv.rtol, atol=sv.atol, max_step=sv.dt_max
            )
        solver = self.solver
        if self.clock() - self.wall0 > sv.max_wall_time:
            limit = sv.max_wall_time
            self._fail(
                Failure.WALL_TIME_LIMIT,
                t,
                limit,
                diagnosis_text(self.model, Failure.WALL_TIME_LIMIT, t, limit),
            )
            return self.diagnosis.text
        try:
            message = solver.step()
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            message = f"{type(exc).__name__}: {exc}"
            solver.status = "failed"
        if solver.status == "failed":
            text = f"{sv.method} failed at t = {solver.t:.6f} s: {message}"
            self._fail(Failure.SOLVER_FAILED, float(solver.t), math.nan, text)
            return text
        t_old, y_old1 = t, y[1]
        t = float(solver.t)
        y = np.array(solver.y, dtype=np.float64)
        self.steps += 1
        width = self.model.sc.conveyor.width
        if on_belt and y_old1 < width <= y[1]:
            # C_s crossed the belt edge y0 = s inside the step: end the step there (dense
            # output), as our schemes do, so belt friction stops at the crossing
            t, y = _edge_crossing(solver.dense_output(), t_old, t, width)
            y[1] = max(y[1], width)
            solver.status = "finished"  # restart from the crossing without belt friction
        fun.on_belt = on_belt
        was_on_belt = on_belt
        self._stop, on_belt = fun.observe(self.reduce, t, y, on_belt)
        self._t, self._y, self.on_belt = t, y, on_belt
        failure = self.reduce.diverged()
        if failure is not None:
            self._fail(failure.kind, failure.t, failure.value, failure.text)
            return failure.text
        if solver.status == "finished":
            fun.after = t  # a new segment starts on a drive breakpoint
            self.solver = None
        elif on_belt != was_on_belt:
            fun.after = -math.inf
            self.solver = None  # the load left the belt: restart without belt friction
        self._check_end()
        return None


__all__ = ["RightHandSide", "ScipyStepper", "solver_class"]
