"""SciPy ``solve_ivp`` baselines on the same right-hand side as our schemes.

``solver.method = scipy:<name>`` (RK45, DOP853, Radau, BDF, LSODA; ``params.SCIPY_METHODS``)
integrates the compiled right-hand side ``kernel.rhs`` (the same forces as the steppers, with
explicit Karnopp friction) with SciPy's ``OdeSolver`` class of that name, stepped one accepted
step at a time so the run is observed exactly like ours: each accepted point goes through the
solve loop's own reductions (``Stepper.observe``, ``kernel.observe``: peaks, impacts, stages,
sorting, energy audit, recorded series) and its divergence checks (``kernel.diverged``).

What the baseline does and does not do, on purpose:

- ``rtol = solver.rtol``, ``atol = solver.atol`` on every state component (SciPy's norm; our
  ``adaptive`` controls the load's six only); ``max_step = solver.dt_max`` (the same cap as
  ``adaptive``); ``first_step`` SciPy's own choice.
- Implicit methods (Radau, BDF) and LSODA get their Jacobian by SciPy's finite differences.
- No event location: contact onset and release, the N >= 0 clamp and stick/slip switches fall
  inside steps and are handled by the error control alone; that is the baseline.
- The solver is restarted (fresh history, same tolerances) at the drive's breakpoints t1 and
  2 t1 (our schemes end steps there too; the drive acceleration jumps at 2 t1, and a
  segment starting there evaluates the right-hand side on its far side) and when the load
  crosses into the chute (belt friction off from then on).
- Stops: the observer's stop (sorted), the end time (``solver.t_end``, or 2 t1 plus
  ``solver.settle_time``), ``solver.max_wall_time``, a solver failure (SciPy's message) or a
  diverged state (``kernel.diverged``: NaN, deep penetration, runaway speed).
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.integrate
from scipy.optimize import brentq

from . import kernel as K
from .params import SCIPY_METHODS
from .stepper import Stepper


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
        self.out = np.zeros((K.N_SLOTS, K.N_COLS))
        self.res = np.zeros(K.N_RES)
        self.modal = np.zeros(md.n_modes)
        self.w = np.zeros(max(2 * n, 2))
        self.wdot = np.zeros(max(2 * n, 2))
        self.nodes = np.zeros((n + 1, 2))
        self.prev = np.zeros(K.N_SLOTS)
        self.lam = np.zeros(3)
        self.on_belt = True
        self.after = -math.inf  # t at or below this is evaluated just past it (a segment start)

    def fill(self, t: float, y: np.ndarray, dy, out, res, modal, lam) -> None:
        md = self.model
        if t <= self.after:
            t = math.nextafter(self.after, math.inf)
        K.rhs(
            md.P,
            md.corners,
            md.normals,
            md.phi,
            md.rigid_modal,
            md.omega,
            md.zeta,
            float(t),
            y,
            self.on_belt,
            dy,
            out,
            res,
            modal,
            self.w,
            self.wdot,
            self.nodes,
            self.prev,
            lam,
        )

    def __call__(self, t, y):
        y = np.ascontiguousarray(y, dtype=np.float64)
        dy = np.empty(self.n)
        self.fill(t, y, dy, self.out, self.res, self.modal, self.lam)
        return dy

    def observe(self, stepper: Stepper, t: float, y: np.ndarray, on_belt: bool):
        """Reduce an accepted point (forces, contacts and belt wrench evaluated there) with the
        solve loop's reductions; ``(stop, on_belt)`` after it."""
        y = np.ascontiguousarray(y, dtype=np.float64)
        dy = np.empty(self.n)
        self.fill(float(t), y, dy, self.out, self.res, self.modal, self.lam)
        return stepper.observe(float(t), y, self.lam, self.out, self.res, on_belt)


def _edge_crossing(dense, t0: float, t1: float, width: float) -> tuple[float, np.ndarray]:
    """Time and state where C_s's y reaches ``width`` on the step's dense output."""
    t = float(brentq(lambda tt: dense(tt)[1] - width, t0, t1, xtol=1e-12))
    return t, np.array(dense(t), dtype=np.float64)


def end_time(sc) -> float:
    """The run's end time: ``solver.t_end``, or the fence cycle 2 t1 plus the settle time."""
    sv = sc.solver
    return sv.t_end if sv.t_end > 0 else 2.0 * sc.drive.t1 + sv.settle_time


def run_solve_ivp(model):
    """Integrate one sorting event with a SciPy OdeSolver; returns a SimulationResult."""
    wall0 = time.perf_counter()
    sc = model.sc
    sv = sc.solver
    cls = solver_class(sv.method)
    t_end = end_time(sc)
    breaks = sorted({b for b in (sc.drive.t1, 2.0 * sc.drive.t1) if 0.0 < b < t_end})
    breaks.append(t_end)
    fun = RightHandSide(model)
    # the reductions and divergence checks of the solve loop, fed SciPy's accepted points
    reduce = Stepper(model)
    on_belt = True
    fun.on_belt = on_belt
    y = model.initial_state()
    stop, on_belt = fun.observe(reduce, 0.0, y, on_belt)
    t = 0.0
    y = np.array(y, dtype=np.float64)
    width = sc.conveyor.width
    steps = 0
    diagnosis = None
    solver = None
    k_break = 0
    while not stop and diagnosis is None and t < t_end - 1e-12:
        while breaks[k_break] <= t + 1e-12:
            k_break += 1
        if solver is None:
            fun.on_belt = on_belt
            solver = cls(
                fun,
                t,
                y,
                breaks[k_break],
                rtol=sv.rtol,
                atol=sv.atol,
                max_step=sv.dt_max,
            )
        if time.perf_counter() - wall0 > sv.max_wall_time:
            diagnosis = f"wall-time limit {sv.max_wall_time:g} s reached at t = {t:.4f} s"
            break
        try:
            message = solver.step()
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            message = f"{type(exc).__name__}: {exc}"
            solver.status = "failed"
        if solver.status == "failed":
            diagnosis = f"{sv.method} failed at t = {solver.t:.6f} s: {message}"
            break
        t_old, y_old1 = t, y[1]
        t = float(solver.t)
        y = np.array(solver.y, dtype=np.float64)
        steps += 1
        if on_belt and y_old1 < width <= y[1]:
            # C_s crossed the belt edge y0 = s inside the step: end the step there (dense
            # output), as our schemes do, so belt friction stops at the crossing
            t, y = _edge_crossing(solver.dense_output(), t_old, t, width)
            y[1] = max(y[1], width)
            solver.status = "finished"  # restart from the crossing without belt friction
        fun.on_belt = on_belt
        was_on_belt = on_belt
        stop, on_belt = fun.observe(reduce, t, y, on_belt)
        failure = reduce.diverged()
        diagnosis = None if failure is None else failure.text
        if solver.status == "finished":
            fun.after = t  # a new segment starts on a drive breakpoint
            solver = None
        elif on_belt != was_on_belt:
            fun.after = -math.inf
            solver = None  # the load left the belt: restart without belt friction
    return reduce.result(steps=steps, diagnosis=diagnosis, wall=time.perf_counter() - wall0)


__all__ = ["RightHandSide", "end_time", "run_solve_ivp", "solver_class"]
