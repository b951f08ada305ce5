"""Compiled peers: CyRK's C++ ODE solvers on the same compiled right-hand side as the SciPy
baselines.

``solver.method = cyrk:<name>`` (LSODA, BDF, Radau, RK45, DOP853, Tsit5; ``params.CYRK_METHODS``)
integrates ``kernel.rhs`` with the C++ solver of that name of CyRK (``nbsolve2_ivp``). The
solver calls a Numba ``@cfunc`` (:data:`rhs_cfunc`, CyRK's diffeq signature ``void(double* dy,
double t, double* y, double* args)``) that calls the compiled ``kernel.rhs``: no Python runs
inside a solve. A SciPy baseline pays a Python call per right-hand side; these peers are the
honest measure of what a compiled general-purpose solver does with the same model.

Same as the SciPy baselines (``baselines``), on purpose:

- ``rtol = solver.rtol``, ``atol = solver.atol`` on every state component, ``max_step =
  solver.dt_max``, the first step the solver's own choice; implicit methods and LSODA build
  their Jacobian by finite differences.
- No event location inside a solve. Restarts at the drive's breakpoints t1 and 2 t1
  (``stepper.segments``: one solve per segment; a segment starting on a breakpoint evaluates
  the right-hand side on its far side) and where the load crosses into the chute.
- Every accepted step goes through the solve loop's reductions (``kernel.observe``,
  ``kernel.diverged``: peaks, impacts, stages, sorting, energy audit, recorded series), here in
  compiled code (:func:`observe_points`) after each segment's solve.

What differs: CyRK's solve of a segment runs to its end in one call, so the belt-edge crossing
is found after the fact from the accepted steps (cubic Hermite interpolation between the two
accepted points around it, with the right-hand side at both, bisected to 1e-12 s); the solve
restarts there without belt friction, and the steps the solver took past the crossing are paid
for and discarded. ``solver.max_wall_time`` is checked between segments and between observed
points (a C++ solve cannot be interrupted); a segment stops at :data:`MAX_STEPS` accepted steps.

CyRK is not a core dependency (it is pinned in requirements/python.txt for the benchmarks):
it is imported when the first peer solve starts (:func:`solve_function`), with a one-line
error naming the install if it is missing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numba
import numpy as np
from numba import carray, njit, types
from numba.extending import intrinsic

from . import kernel as K
from .observed import ObservedStepper
from .params import CYRK_METHODS
from .stepper import Failure, diagnosis_text

CYRK_SUCCESS = (1, 2)  # CyRK's statuses of a finished solve (integrated, event terminated)
NO_RESULT = -1000  # our status of a solve that returned no result
MAX_STEPS = 2_000_000  # accepted steps of one segment's solve before it is stopped as failed

# the status of :func:`observe_points`
OBS_END = 0  # every point of the segment observed
OBS_PAUSE = 1  # the requested number of points observed
OBS_STOP = 2  # the observer stops the run (sorted)
OBS_RESTART = 3  # the load left the belt: restart from the observed point without belt friction
OBS_GROW = 4  # a reduction buffer is full: grow it and go on
OBS_FAILED = 5  # a diverged state (counters.diag holds the code)


def solver_name(method: str) -> str:
    """CyRK's name of the ``cyrk:<name>`` method."""
    if method not in CYRK_METHODS:
        raise ValueError(
            f"solver.method {method!r} is not a compiled peer: one of {', '.join(CYRK_METHODS)}"
        )
    return method.split(":", 1)[1]


# -- the right-hand side as CyRK's diffeq -------------------------------------------------------
def _pointer_to(nbtype):
    """An intrinsic turning an address (int64) into a pointer to ``nbtype``."""

    @intrinsic
    def as_pointer(typingctx, addr):
        sig = types.CPointer(nbtype)(types.int64)

        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

        return sig, codegen

    return as_pointer


_f64_at = _pointer_to(types.float64)
_params_at = _pointer_to(numba.from_dtype(K.PARAMS))
_contact_at = _pointer_to(numba.from_dtype(K.CONTACT))
_result_at = _pointer_to(numba.from_dtype(K.RESULT))

# the args buffer of the diffeq: three scalars, then (address, rows, columns) of each array
A_N_STATE, A_ON_BELT, A_AFTER = 0, 1, 2
# (the fields of a ForceModel and of an Evaluation, in their order)
_ARRAYS = K.ForceModel._fields + K.Evaluation._fields
N_ARGS = 3 + 3 * len(_ARRAYS)


@njit(inline="always")
def _vec(args, k):
    j = 3 + 3 * k
    return carray(_f64_at(np.int64(args[j])), (np.int64(args[j + 1]),))


@njit(inline="always")
def _slots(args, k):
    j = 3 + 3 * k
    return carray(_contact_at(np.int64(args[j])), (np.int64(args[j + 1]),))


@njit(inline="always")
def _result(args, k):
    return carray(_result_at(np.int64(args[3 + 3 * k])), (1,))


@njit(inline="always")
def _mat(args, k):
    j = 3 + 3 * k
    return carray(_f64_at(np.int64(args[j])), (np.int64(args[j + 1]), np.int64(args[j + 2])))


@numba.cfunc(
    types.void(
        types.CPointer(types.float64),
        types.float64,
        types.CPointer(types.float64),
        types.CPointer(types.float64),
    ),
    cache=True,
)
def rhs_cfunc(dy_ptr, t, y_ptr, args_ptr):
    """CyRK's diffeq: ``kernel.rhs`` on the arrays whose addresses the args buffer holds."""
    args = carray(args_ptr, (N_ARGS,))
    n = np.int64(args[A_N_STATE])
    after = args[A_AFTER]
    if t <= after:
        t = np.nextafter(after, np.inf)
    model = K.ForceModel(
        carray(_params_at(np.int64(args[3])), (1,)), _mat(args, 1), _mat(args, 2), _mat(args, 3),
        _vec(args, 4), _vec(args, 5), _vec(args, 6),
    )  # fmt: skip
    ev = K.Evaluation(
        _slots(args, 7), _result(args, 8), _vec(args, 9), _vec(args, 10), _vec(args, 11),
        _mat(args, 12), _vec(args, 13), _vec(args, 14),
    )  # fmt: skip
    K.rhs(model, t, carray(y_ptr, (n,)), args[A_ON_BELT] != 0.0, carray(dy_ptr, (n,)), ev)


# -- the observation of a segment's accepted points -------------------------------------------
@njit(cache=True)
def _hermite(t0, y0, d0, t1, y1, d1, t, out):
    """The cubic Hermite interpolant of two accepted points (states and derivatives) at t."""
    h = t1 - t0
    s = (t - t0) / h
    s2 = s * s
    s3 = s2 * s
    a, b, c, d = 2 * s3 - 3 * s2 + 1, (s3 - 2 * s2 + s) * h, -2 * s3 + 3 * s2, (s3 - s2) * h
    for k in range(out.shape[0]):
        out[k] = a * y0[k] + b * d0[k] + c * y1[k] + d * d1[k]


@njit(cache=True)
def _crossing(t0, y0, d0, t1, y1, d1, width, out):
    """Time where the interpolant's y reaches ``width`` (bisection to 1e-12 s); state in out."""
    lo, hi = t0, t1
    while hi - lo > 1e-12:
        mid = 0.5 * (lo + hi)
        _hermite(t0, y0, d0, t1, y1, d1, mid, out)
        if out[1] < width:
            lo = mid
        else:
            hi = mid
    _hermite(t0, y0, d0, t1, y1, d1, hi, out)
    return hi


@njit(cache=True)
def observe_points(
    model, scratch, reduce, ts, ys, k, count, on_belt, after, width, dprev, dy, point
):  # fmt: skip
    """Reduce the accepted points ``ts[k:], ys[k:]`` of a segment's solve (at most ``count``) as
    the SciPy baselines' points are: the right-hand side evaluated at each (contact slots,
    resultants, belt wrench), ``kernel.observe``, ``kernel.diverged``. ``dprev``: dy at point
    k - 1 (the segment's first point: computed here when k == 1). A crossing of the belt edge
    between two points ends the segment at the crossing (:func:`_crossing`, its state in
    ``point``). Returns (OBS_* status, next k, on_belt)."""
    P, normals = model.params, model.normals
    out, res, lam = scratch.contacts, scratch.resultant, scratch.belt
    (settings, counters, figures, times, states, belt_wrench, contact_rows, resultant_rows,
     impact_rows, stage_rows, record) = reduce  # fmt: skip
    n = ts.shape[0]
    if k == 1:
        t0 = ts[0]
        if t0 <= after:
            t0 = np.nextafter(after, np.inf)
        K.rhs(model, t0, ys[0], on_belt, dprev, scratch)
    done = 0
    while k < n:
        if done == count:
            return OBS_PAUSE, k, on_belt
        if (
            counters[0].n_impacts >= impact_rows.shape[0]
            or counters[0].n_stages >= stage_rows.shape[0]
            or counters[0].n_rec >= record.shape[0]
        ):
            return OBS_GROW, k, on_belt
        t = ts[k]
        y = ys[k]
        K.rhs(model, t, y, on_belt, dy, scratch)
        crossed = on_belt and ys[k - 1, 1] < width <= y[1]
        if crossed:
            t = _crossing(ts[k - 1], ys[k - 1], dprev, t, y, dy, width, point)
            point[1] = max(point[1], width)
            y = point
            K.rhs(model, t, y, on_belt, dy, scratch)
        i = counters[0].cur
        times[i] = t
        states[i] = y
        belt_wrench[i] = lam
        contact_rows[i] = out
        resultant_rows[i] = res
        was_on_belt = on_belt
        stop, on_belt = K.observe(P, normals, settings, counters, figures, times, states,
                                  belt_wrench, contact_rows, resultant_rows, impact_rows,
                                  stage_rows, record, i, on_belt)  # fmt: skip
        code = K.diverged(P, settings, figures, times[i], states[i], resultant_rows[i])
        k += 1
        done += 1
        if code != K.DIAG_NONE:
            counters[0].diag = code
            return OBS_FAILED, k, on_belt
        if stop:
            return OBS_STOP, k, on_belt
        if crossed or on_belt != was_on_belt:
            return OBS_RESTART, k, on_belt
        dprev[:] = dy
    return OBS_END, k, on_belt


_SOLVE = None


def solve_function():
    """The compiled solve of one segment with CyRK (built on first use: imports CyRK).

    It calls CyRK's C API for Numba (``CyRK.nb.numba_solver``: the functions ``nbsolve2_ivp``
    calls) directly, without its result class, whose compilation takes ~10 s per process: a
    function that calls C through ctypes cannot be cached on disk. Returns (CyRK status,
    accepted times, states)."""
    global _SOLVE
    if _SOLVE is not None:
        return _SOLVE
    try:
        # lazy: CyRK is a benchmark dependency, not a core one
        from CyRK.cy.pyhelpers import find_ode_method_int, get_error_message
        from CyRK.nb import numba_solver as C
    except ImportError as exc:
        raise ImportError(
            "the cyrk:* methods need CyRK (pip install CyRK==0.20.0, in requirements/python.txt)"
        ) from exc
    cysolve, c_free = C.c_numba_cysolve_ivp, C.c_free
    c_size, c_num_dy, c_status = C.c_get_size, C.c_get_num_dy, C.c_get_status
    c_t, c_y = C.c_get_t_ptr, C.c_get_y_ptr
    dbl = 8

    @njit
    def solve(addr, t0, t1, y0, method, args, rtol, atol, max_step, max_steps):
        rtols = np.full(1, rtol)
        atols = np.full(1, atol)
        none = np.empty(0)
        ptr = cysolve(
            np.uint64(addr), t0, t1, y0.ctypes.data, np.uint64(y0.size), np.int32(method),
            np.uint64(0), np.uint64(0), args.ctypes.data, np.uint64(args.size * dbl),
            np.uint64(max_steps), np.uint64(2000), False, none.ctypes.data, np.uint64(0),
            0, 0, np.uint64(0), rtols.ctypes.data, np.uint64(1), atols.ctypes.data,
            np.uint64(1), max_step, 0.0, True,
        )  # fmt: skip
        if ptr == 0:
            return NO_RESULT, np.empty(0), np.empty((0, y0.size))
        status = c_status(ptr)
        n = c_size(ptr)
        ts = carray(c_t(ptr), (n,)).copy()
        ys = carray(c_y(ptr), (n, c_num_dy(ptr))).copy()
        c_free(ptr)
        return status, ts, ys

    _SOLVE = (solve, find_ode_method_int, get_error_message)
    return _SOLVE


class CyrkStepper(ObservedStepper):
    """One sorting event integrated by a CyRK solver, stepped as ``stepper.Stepper`` steps our
    schemes (``stepper.SolveStepper``): :meth:`step` is one accepted step (a segment is solved
    when its first point is asked for), observed by the solve loop's reductions (a
    :class:`Stepper` that integrates nothing, :attr:`reduce`); :meth:`advance` observes a
    segment's points in one compiled call. End time and breakpoints are ``stepper.segments``."""

    def __init__(self, model, clock: Callable[[], float] = time.perf_counter):
        super().__init__(model, clock)
        self.name = solver_name(model.sc.solver.method)
        self._solve, method_int, self._message = solve_function()
        self._method = int(method_int(self.name))
        md = model
        n_el = md.n_el
        self.scratch = K.Evaluation(
            K.zero_slots(),
            K.zero_result(),
            np.zeros(md.n_modes),
            np.zeros(max(2 * n_el, 2)),
            np.zeros(max(2 * n_el, 2)),
            np.zeros((n_el + 1, 2)),
            np.zeros(K.N_SLOTS),
            np.zeros(3),
        )
        arrays = (md.P, md.corners, md.normals, md.phi, md.rigid_modal, md.omega, md.zeta)
        self.arrays = K.ForceModel(*(np.ascontiguousarray(a) for a in arrays))
        self.args = np.zeros(N_ARGS)
        self.args[A_N_STATE] = md.n_state
        for k, a in enumerate(self.arrays + self.scratch):
            shape = (*a.shape, 0, 0)
            self.args[3 + 3 * k : 6 + 3 * k] = (a.ctypes.data, shape[0], shape[1])
        self.dprev = np.zeros(md.n_state)
        self.dy = np.zeros(md.n_state)
        self.point = np.zeros(md.n_state)
        self._seg: tuple[np.ndarray, np.ndarray] | None = None  # the current segment's points
        self._k = 1
        self._after = -math.inf
        # the initial point, reduced as the baselines reduce it
        y = self._y
        self._observe(np.zeros(2), np.stack([y, y]), 1, 1)
        self.steps = 0
        self._after = -math.inf
        self._seg = None

    def step(self) -> str | None:
        """One accepted step, reduced; None, or the diagnosis text when the solve failed.
        Raises once ended."""
        if self.status != "running":
            raise RuntimeError(f"step() on a {self.status} solve")
        self._advance_points(1)
        return None if self.diagnosis is None else self.diagnosis.text

    def advance(self, t_target: float = math.inf) -> bool:
        """Step until the accepted time reaches ``t_target`` (or the end); False once the
        solve has ended."""
        while self.status == "running":
            if self._t >= t_target:
                return True
            self._advance_points(1 if math.isfinite(t_target) else -1)
        return False

    # -- internals -----------------------------------------------------------------------------

    def _advance_points(self, count: int) -> None:
        """Observe up to ``count`` accepted points (all of the segment: -1), solving the next
        segment first when the current one is used up."""
        sv = self.model.sc.solver
        if self.clock() - self.wall0 > sv.max_wall_time:
            limit = sv.max_wall_time
            text = diagnosis_text(self.model, Failure.WALL_TIME_LIMIT, self._t, limit)
            self._fail(Failure.WALL_TIME_LIMIT, self._t, limit, text)
            return
        if self._seg is None and not self._solve_segment():
            return
        ts, ys = self._seg
        self._observe(ts, ys, self._k, count)

    def _solve_segment(self) -> bool:
        breaks = self.breakpoints
        t = self._t
        while breaks[self._k_break] <= t + 1e-12:
            self._k_break += 1
        sv = self.model.sc.solver
        self.args[A_ON_BELT] = float(self.on_belt)
        self.args[A_AFTER] = self._after
        status, ts, ys = self._solve(
            rhs_cfunc.address,
            t,
            float(breaks[self._k_break]),
            np.array(self._y, dtype=np.float64),
            self._method,
            self.args,
            float(sv.rtol),
            float(sv.atol),
            float(sv.dt_max),
            MAX_STEPS,
        )
        if status not in CYRK_SUCCESS or len(ts) < 2:
            why = self._message(status) if status != NO_RESULT else "no result"
            text = f"{sv.method} failed after t = {t:.6f} s: {why} (CyRK status {status})"
            self._fail(Failure.SOLVER_FAILED, t, math.nan, text)
            return False
        self._seg = (ts, ys)
        self._k = 1
        return True

    def _observe(self, ts, ys, k, count) -> None:
        r = self.reduce
        reduce_arrays = (
            r.settings, r.counters, r.figures, r.times, r.states, r.belt_wrench, r.contact_rows,
            r.resultant_rows, r.impact_rows, r.stage_rows, r.record,
        )  # fmt: skip
        status, k_next, on_belt = observe_points(
            self.arrays,
            self.scratch,
            reduce_arrays,
            ts,
            ys,
            k,
            count,
            self.on_belt,
            self._after,
            self.model.sc.conveyor.width,
            self.dprev,
            self.dy,
            self.point,
        )
        observed = k_next - k
        self.steps += observed
        self._k = k_next
        self.on_belt = bool(on_belt)
        self._stop = status == OBS_STOP
        if observed:
            i = int(r.counters["cur"][0])
            self._t = float(r.times[i])
            self._y = np.array(r.states[i])
        if status == OBS_GROW:
            r._grow()
            return
        if status == OBS_FAILED:
            fail = r.diverged()
            self.diagnosis = fail
            self.status = "failed"
            return
        if status == OBS_RESTART:
            self._after = self._t
            self._seg = None
        elif status == OBS_END:
            self._after = self._t  # the next segment starts on a drive breakpoint
            self._seg = None
        self._check_end()


__all__ = ["CyrkStepper", "rhs_cfunc", "solver_name", "observe_points"]
