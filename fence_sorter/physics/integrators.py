"""Time integration of one sorting event: the schemes and their event-driven control loop.

Methods (``solver.method``; docs/accuracy/ measures each):

- ``trapezoidal`` (fixed step ``solver.dt``): load by the trapezoidal rule, implicit in the
  contact forces and belt friction; fence modes propagated exactly (Van Loan) for a modal force
  linear over the step. A-stable, no numerical damping, second order.
- ``generalized_alpha`` (fixed step): Chung-Hulbert generalized-alpha on load and modes with
  high-frequency dissipation set by ``solver.rho_inf`` (1: none, 0: asymptotic annihilation);
  second order. The structural-dynamics standard (as in Chrono's HHT and Abaqus).
- ``adaptive`` (the default): the trapezoidal step with local error control: Milne's device
  (the difference between the trapezoidal corrector and a variable-step Adams-Bashforth-2
  predictor estimates the local error), ``solver.rtol``/``solver.atol`` on the load's state,
  steps between ``solver.min_dt`` and ``solver.dt_max``.

All three share the events that would otherwise cost the schemes their order: contact onset and
release (a fence contact's law (16) crossing N = 0, which includes the N >= 0 clamp engaging)
are located by regula falsi so a step ends on them; the drive's acceleration jumps (0, t1, 2 t1)
are step ends; belt and fence stick/slip is implicit (exact stick, the paper's 1e-6 m/s Karnopp
window kept); C_s crossing the sorting line y0 = s ends a step (the belt stops carrying the
load there). A step whose contact iteration fails is
halved; a step this small that still fails straddles a switch and is taken and counted (forced).

Divergence (NaN, runaway speed, deep penetration, step below min_dt, wall-time limit) stops the
solve with a diagnosis; nothing past it is returned as data.

The loop here is the Python one (``solver.engine = python``; the soft-real-time line steps it as
a generator). ``kernel.solve`` is the same loop compiled, which :func:`simulate.simulate` runs by
default for every scheme (``engine.py``); a change to one must be made to the other
(test/physics/test_engine.py compares them).
"""

from __future__ import annotations

import math
import time

import numpy as np

from . import kernel as K
from .contacts import STAGE_SORTED, classify
from .engine import CompiledSolve, generalized_alpha_coefficients, uses_compiled

EVENT_TOL = 1e-10  # a located onset's step ends with 0 < D <= EVENT_TOL [m]
EVENT_SORT = 3  # C_s crossing the sorting line y0 = s (belt friction ends there)
TRACE = 8  # accepted points the compiled loop runs ahead of a stepping observer (a soft-real-time
# caller checks its wall deadline between points: 8 keeps one run-ahead near 0.1-0.2 ms)


class Propagators:
    """Exact one-step maps of the damped modes (``kernel.modal_propagators``), cached per h."""

    def __init__(self, omega: np.ndarray, zeta: np.ndarray):
        self.omega, self.zeta = omega, zeta
        self.m = len(omega)
        self._cache: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def get(self, h: float):
        hit = self._cache.get(h)
        if hit is not None:
            return hit
        m = self.m
        out = (np.empty((m, 2, 2)), np.empty((m, 2)), np.empty((m, 2)))
        K.modal_propagators(self.omega, self.zeta, h, *out)
        if len(self._cache) > 256:
            self._cache.clear()
        self._cache[h] = out
        return out


class State:
    """One accepted (or trial) point: state vector, belt wrench, forces and contacts there."""

    __slots__ = ("t", "y", "lam", "out", "res", "modal", "acc")

    def __init__(self, n_state: int, m: int):
        self.t = 0.0
        self.y = np.zeros(n_state)
        self.lam = np.zeros(3)
        self.out = np.zeros((K.N_SLOTS, K.N_COLS))
        self.res = np.zeros(K.N_RES)
        self.modal = np.zeros(m)
        self.acc = np.zeros(3 + m)  # (x, y, phi, eta): algorithmic accelerations (gen-alpha)

    def copy_from(self, o: State) -> None:
        self.t = o.t
        self.y[:] = o.y
        self.lam[:] = o.lam
        self.out[:] = o.out
        self.res[:] = o.res
        self.modal[:] = o.modal
        self.acc[:] = o.acc


class Scheme:
    """A one-step map (state in, state out) over the model's kernel arrays."""

    def __init__(self, model, method: str):
        sv = model.sc.solver
        self.model = model
        self.method = method
        self.tol = sv.tolerance
        self.max_iter = sv.max_iterations
        # exact modal maps depend only on (omega, zeta, h): kept on the model, so repeated
        # solves of one model (controller, optimiser, benchmarks) reuse them
        props = getattr(model, "propagators", None)
        if props is None:
            props = model.propagators = Propagators(model.omega, model.zeta)
        self.props = props
        self.coef = generalized_alpha_coefficients(sv.rho_inf)
        n = model.n_el
        self.w = np.zeros(max(2 * n, 2))
        self.wdot = np.zeros(max(2 * n, 2))
        self.nodes = np.zeros((n + 1, 2))
        self.prev = np.zeros(K.N_SLOTS)
        self.ya = np.zeros(model.n_state)
        self.work = np.zeros(K.trapezoidal_work_shape(model.n_modes))

    def initialize(self, st: State, on_belt: bool) -> None:
        """Forces at the initial state; belt wrench by Karnopp; consistent accelerations."""
        md = self.model
        self.prev[:] = math.nan
        K.evaluate(
            md.P,
            md.corners,
            md.normals,
            md.phi,
            md.rigid_modal,
            st.t,
            0.0,
            st.y,
            st.lam,
            0.0,
            self.prev,
            st.out,
            st.res,
            st.modal,
            self.w,
            self.wdot,
            self.nodes,
        )
        y, r = st.y, st.res
        if on_belt:
            st.lam[:] = K.karnopp_belt(md.P, y[3] - md.belt, y[4], y[5], r[0], r[1], r[2])
            if math.hypot(y[3] - md.belt, y[4]) <= md.sc.contact.v_min and abs(y[5]) <= (
                md.sc.contact.phidot_min
            ):
                st.lam[:] = K.stick_wrench(md.P, r[0], r[1], r[2])
        self.accelerations(st)

    def accelerations(self, st: State, jump: float = 0.0) -> None:
        """Accelerations consistent with the forces at ``st`` (``jump``: the drive's
        acceleration jump to add when restarting at 2 t1)."""
        md = self.model
        m = md.n_modes
        st.acc[0] = (st.res[0] + st.lam[0]) / md.mass
        st.acc[1] = (st.res[1] + st.lam[1]) / md.mass
        st.acc[2] = (st.res[2] + st.lam[2]) / md.inertia
        if m:
            eta, etad = st.y[6 : 6 + m], st.y[6 + m :]
            st.acc[3:] = (
                st.modal
                - md.rigid_modal * jump
                - md.omega**2 * eta
                - 2.0 * md.zeta * md.omega * etad
            )

    def step(self, h: float, a: State, b: State, jump: float, on_belt: bool, force: bool) -> int:
        md = self.model
        if self.method == "generalized_alpha":
            status = K.generalized_alpha_step(
                md.P,
                md.corners,
                md.normals,
                md.phi,
                md.rigid_modal,
                md.omega,
                md.zeta,
                self.coef,
                h,
                a.t,
                a.y,
                a.acc,
                a.lam,
                on_belt,
                self.tol,
                self.max_iter,
                force,
                b.y,
                b.acc,
                b.lam,
                b.out,
                b.res,
                b.modal,
                self.w,
                self.wdot,
                self.nodes,
                self.prev,
                self.ya,
            )
        else:
            status = K.trapezoidal_step(
                md.P,
                md.corners,
                md.normals,
                md.phi,
                md.rigid_modal,
                self.props.get(h),
                h,
                a.t,
                a.y,
                a.res,
                a.lam,
                a.modal,
                a.out,
                jump,
                on_belt,
                self.tol,
                self.max_iter,
                force,
                b.y,
                b.lam,
                b.out,
                b.res,
                b.modal,
                self.w,
                self.wdot,
                self.nodes,
                self.prev,
                self.work,
            )
            if status != K.STEP_REJECTED:
                b.acc[0] = (b.res[0] + b.lam[0]) / md.mass
                b.acc[1] = (b.res[1] + b.lam[1]) / md.mass
                b.acc[2] = (b.res[2] + b.lam[2]) / md.inertia
        b.t = a.t + h
        return status


def _local_error(a: State, b: State, prev_v, prev_a, r: float, h: float, scale):
    """Scaled local error of the trapezoidal step a -> b and the order of the estimate.

    With history (r = h / h_prev > 0), Milne's device: TR's local error is -h^3 y'''/12, a
    variable-step AB2 predictor's is h^3 y''' (1/6 + 1/(4r)), so the error is r/(3(r+1)) times
    corrector minus predictor (order 3). Without history (the start, after an event or a drive
    breakpoint) the explicit Euler predictor gives the conservative order-2 estimate
    |corrector - predictor|. Each component is scaled by atol + rtol * a block magnitude
    (``kernel.milne_error``: position |r| or 1 m, yaw |phi| or 1 rad, velocity |v| or the belt
    speed, yaw rate |phidot| or belt / load size), so a component passing through zero does not
    shrink the tolerance to atol.
    """
    atol, rtol, v_ref, om_ref = scale
    err = K.milne_error(a.y, a.acc, b.y, prev_v, prev_a, r, h, atol, rtol, v_ref, om_ref)
    return err, (3.0 if r > 0.0 else 2.0)


class Integrator:
    """Event-driven control loop shared by the fixed-step and adaptive schemes."""

    def __init__(self, model):
        self.model = model
        sc = model.sc
        sv = sc.solver
        self.sv = sv
        self.method = sv.method
        self.adaptive = sv.method == "adaptive"
        self.scheme = Scheme(model, "trapezoidal" if self.adaptive else sv.method)
        self.h_nom = sv.dt_max if self.adaptive else sv.dt
        t_cycle = 2.0 * sc.drive.t1
        self.t_end = sv.t_end if sv.t_end > 0 else t_cycle + sv.settle_time
        self.breaks = sorted({b for b in (sc.drive.t1, t_cycle) if 0.0 < b < self.t_end})
        self.breaks.append(self.t_end)
        n = model.n_state
        m = model.n_modes
        self.cur, self.trial, self.loc = State(n, m), State(n, m), State(n, m)
        self.before = State(n, m)
        self.width = sc.conveyor.width
        # solver.engine = compiled: kernel.solve takes the steps, this loop only replays them
        self.compiled = uses_compiled(sc)
        self.forced = 0
        self.events = 0
        self.outcome: tuple[float, str | None, int, int] | None = None
        body = model.body
        v_ref = max(model.belt, 0.1)
        self.err_scale = (sv.atol, sv.rtol, v_ref, v_ref / min(body.length_a, body.width_b))

    def _snap(self, h: float) -> float:
        """Round an adaptive step down onto the ladder dt_max 2^(-k/4), so the exact modal
        propagators (a matrix exponential per mode) are reused instead of recomputed."""
        k = math.ceil(4.0 * math.log2(self.h_nom / h) - 1e-9)
        return self.h_nom * 2.0 ** (-k / 4.0)

    def jump_at(self, t: float) -> float:
        return (
            -0.5 * self.model.sc.drive.alpha_k * (math.pi / self.model.sc.drive.t1) ** 2
            if abs(t - 2.0 * self.model.sc.drive.t1) <= 1e-12
            else 0.0
        )

    def _locate(self, h: float, on_belt: bool, slot: int, kind: int, g0: float, g1: float):
        """Shorten the step to end just past the sign change of ``slot``'s event function.

        Regula falsi (Illinois) until an onset step ends within ``EVENT_TOL`` m of D = 0 (so
        w_n is read at the onset), a slide-off or sort crossing step ends within the iteration
        tolerance of its line, or a bracket is below 1e-7 of the step.
        The located trial is left in ``self.trial``; returns the step taken.
        """
        a, sch = self.cur, self.scheme
        onset = kind == K.EVENT_ONSET
        sign0 = g0 > 0.0
        lo, g_lo = 0.0, g0
        hi, g_hi = h, g1
        jump = self.jump_at(a.t)
        best = None
        # a corner sliding off the tip drops its force from N(D) to zero: end that step just
        # before the slide-off, within the contact iteration's tolerance of the tip (the force
        # there is the peak the step would otherwise skip); the next step starts within the
        # tolerance, and another step before the tip would only creep up on it: it is stepped
        # just past the tip instead (2x the secant's step, not clamped to 1e-3 of the bracket,
        # which took ~5 trial steps), done once it ends within the tolerance past the tip
        keep_before = kind == K.EVENT_SLIDE_OFF and g0 > sch.tol
        cross = kind == K.EVENT_SLIDE_OFF and not keep_before
        before = None
        # Illinois variant: the end kept twice in a row has its value halved in the secant, so
        # the bracket shrinks from both sides (plain regula falsi stalls on a curved event
        # function: 60 trial steps for one slide-off or onset)
        f_lo, f_hi, last = g_lo, g_hi, 0
        # the slide-off end position jumps where a friction branch switches inside the trial
        # step (~1.6e-6 m on positioned_stiff), and the Illinois secant across that jump crept
        # up on the tip from below (10 trial steps); the lo side is smooth: after a lo end its
        # secant through the last two lo ends, aimed at tol / 2 before the tip, when it lands
        # inside the bracket
        lo_prev, g_lo_prev = lo, g_lo
        for _ in range(60):
            if hi - lo <= 1e-7 * h or (onset and g_hi <= EVENT_TOL):
                break
            if before is not None and g_lo <= sch.tol:
                break  # the step before the slide-off ends within tolerance of the tip
            if cross and best is not None and -g_hi <= sch.tol:
                break  # the step across it ends within tolerance past the tip
            if kind == EVENT_SORT and best is not None and -g_hi <= sch.tol:
                break  # the sort crossing: within tolerance past the sorting line
            h_loc = lo + (hi - lo) * (f_lo / (f_lo - f_hi))
            if cross and last == 0:
                h_loc = min(2.0 * h_loc, hi)
            else:
                h_loc = min(max(h_loc, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
            if keep_before and last == -1 and g_lo_prev > g_lo:
                h_sec = lo + (g_lo - 0.5 * sch.tol) * (lo - lo_prev) / (g_lo_prev - g_lo)
                if lo < h_sec < hi:
                    h_loc = h_sec
            st = sch.step(h_loc, a, self.loc, jump, on_belt, False)
            if st == K.STEP_REJECTED:
                break
            if kind == EVENT_SORT:
                g = self.width - self.loc.y[1]
            else:
                g = K.event_value(self.model.P, self.loc.out, slot, kind)
            if math.isnan(g):
                break
            if (g > 0.0) != sign0:
                hi, g_hi, f_hi = h_loc, g, g
                if last == 1:
                    f_lo *= 0.5
                last = 1
                best = h_loc
                self.trial.copy_from(self.loc)
            else:
                lo_prev, g_lo_prev = lo, g_lo
                lo, g_lo, f_lo = h_loc, g, g
                if last == -1:
                    f_hi *= 0.5
                last = -1
                if keep_before:
                    before = h_loc
                    self.before.copy_from(self.loc)
        self.events += 1
        if before is not None:
            self.trial.copy_from(self.before)
            return before
        return best if best is not None else h

    def run(self, observer) -> tuple[float, str | None, int, int]:
        """Integrate to the end (or the observer's stop); returns (t, diagnosis, steps, rejected).

        ``observer(state, on_belt) -> (stop, on_belt)`` is called at every accepted point.
        """
        for _ in self.stepping(observer):
            pass
        return self.outcome

    def advance(self, stepper, t_target: float) -> bool:
        """Step ``stepper`` (from :meth:`stepping`) until the accepted time reaches ``t_target``;
        False once the solve has ended (see :attr:`outcome`). For soft-real-time stepping."""
        while self.cur.t < t_target - 1e-12:
            if next(stepper, None) is None:
                return False
        return True

    def stepping(self, observer):
        """Generator form of :meth:`run`: yields the accepted time after every step, and leaves
        ``(t, diagnosis, steps, rejected)`` in :attr:`outcome` when the solve ends.

        With ``solver.engine = compiled`` the steps are taken by ``kernel.solve`` (the same
        loop compiled), ``TRACE`` accepted points at a time, and each is handed to ``observer``
        and yielded in turn (:attr:`cur` is the point handed over): the same points, figures and
        outcome as the Python loop.
        """
        if self.compiled:
            return self._replay(observer)
        return self._stepping(observer)

    def _replay(self, observer):
        """:meth:`stepping` on the compiled loop."""
        solve = CompiledSolve(self.model, trace=TRACE)
        limit = self.sv.max_wall_time
        a = self.cur
        initial = True  # the initial point is observed, not yielded (as in the Python loop)
        diagnosis = None
        busy, resumed = 0.0, time.perf_counter()
        while True:
            rows = solve.run_ahead()
            ctl = solve.ctl
            self.forced, self.events = int(ctl[K.I_FORCED]), int(ctl[K.I_EVENTS])
            last_diverged = solve.done and solve.diverged_last
            for k in range(rows):
                observer(a, solve.load(k, a))
                if initial:
                    initial = False
                    continue
                if last_diverged and k == rows - 1:
                    break  # the diverged point: observed, not yielded (nothing past it is data)
                busy += time.perf_counter() - resumed
                yield a.t
                resumed = time.perf_counter()
            solve.clear_trace()
            if solve.done:
                diagnosis = solve.outcome()[1]
                break
            if busy + time.perf_counter() - resumed > limit:
                diagnosis = f"wall-time limit {limit:g} s reached at t = {a.t:.4f} s"
                break
        ctl = solve.ctl
        self.outcome = (a.t, diagnosis, int(ctl[K.I_STEPS]), int(ctl[K.I_REJECTED]))

    def _stepping(self, observer):
        """:meth:`stepping` on this (Python) loop."""
        md, sv, sch = self.model, self.sv, self.scheme
        a, b = self.cur, self.trial
        on_belt = True
        a.t = 0.0
        a.y[:] = md.initial_state()
        sch.initialize(a, on_belt)
        stop, on_belt = observer(a, on_belt)
        # solver.max_wall_time counts the time spent stepping, not the pauses between the
        # chunks a soft-real-time caller advances (see advance)
        busy, resumed = 0.0, time.perf_counter()
        h = self.h_nom if not self.adaptive else min(self.h_nom, sv.dt)
        steps = rejected = 0
        next_break = 0
        diagnosis = None
        h_cap, clean = self.h_nom, 0
        # adaptive: Milne's device needs the previous point's rates
        prev_v = np.zeros(3)
        prev_a = np.zeros(3)
        h_prev = 0.0  # 0: no history (start, after an event or a breakpoint)
        while not stop and a.t < self.t_end - 1e-12:
            if busy + time.perf_counter() - resumed > sv.max_wall_time:
                diagnosis = f"wall-time limit {sv.max_wall_time:g} s reached at t = {a.t:.4f} s"
                break
            while self.breaks[next_break] <= a.t + 1e-12:
                next_break += 1
            to_break = self.breaks[next_break] - a.t
            h_try = min(h, to_break)
            if self.adaptive:
                # do not step over a contact: end the step by the time the closest gap closes
                # at its closing speed (floor 10 min_dt: a grazing approach does not stall);
                # resolve a lightly damped contact oscillation (kernel.oscillation_step)
                cap = min(
                    K.time_to_contact(a.out), K.oscillation_step(self.model.P, a.out, sv.rtol)
                )
                h_try = min(h_try, max(cap, 10.0 * sv.min_dt))
            tiny = h_try <= 1e-3 * self.h_nom if not self.adaptive else h_try <= 4.0 * sv.min_dt
            status = sch.step(h_try, a, b, self.jump_at(a.t), on_belt, tiny)
            if status == K.STEP_REJECTED:
                rejected += 1
                h = h_try / 2.0
                # the contact iteration does not contract at this step: cap the adaptive step one
                # ladder rung below it, and lift the cap one rung per 4 clean steps
                h_cap, clean = h_try * 2.0**-0.25, 0
                if h < sv.min_dt:
                    diagnosis = (
                        f"step size fell below solver.min_dt={sv.min_dt:g} s at t = {a.t:.6f} s: "
                        "the contact iteration does not converge (contact too stiff for the step?)"
                    )
                    break
                continue
            if status == K.STEP_FORCED:
                self.forced += 1
            h_taken = h_try
            # contact onset / release inside the step: end the step on it
            slot, kind, g0, g1 = K.first_event(self.model.P, a.out, b.out)
            if slot < 0 and on_belt and a.y[1] < self.width <= b.y[1]:
                # C_s crosses the belt edge y0 = s: the belt stops carrying the load there
                slot, kind, g0, g1 = -1, EVENT_SORT, self.width - a.y[1], self.width - b.y[1]
            located = False
            if (slot >= 0 or kind == EVENT_SORT) and h_try > 1e-9:
                h_taken = self._locate(h_try, on_belt, slot, kind, g0, g1)
                located = True
            if self.adaptive:
                # the solution is smooth on [t, t + h_taken] (a located event is at its end)
                r = h_taken / h_prev if h_prev > 0.0 else 0.0
                err, order = _local_error(a, b, prev_v, prev_a, r, h_taken, self.err_scale)
                if err > 1.0 and h_taken > 4.0 * sv.min_dt:
                    rejected += 1
                    h = self._snap(h_taken * max(0.2, 0.9 * err ** (-1.0 / order)))
                    continue
                if not located:
                    grow = min(4.0, 0.9 * max(err, 1e-12) ** (-1.0 / order))
                    clean += 1
                    if clean >= 4 and h_cap < self.h_nom:
                        h_cap, clean = h_cap * 2.0**0.25, 0
                    h = self._snap(min(self.h_nom, h_cap, h_taken * grow))
            else:
                h = min(self.h_nom, 2.0 * h_try)
            # accept
            prev_v[:] = a.y[3:6]
            prev_a[:] = a.acc[:3]
            h_prev = h_taken
            if located or abs(a.t + h_taken - self.breaks[next_break]) <= 1e-12:
                h_prev = 0.0  # the rates have a kink here: restart the error history
            if self.method == "generalized_alpha" and h_prev == 0.0:
                # restart from consistent accelerations after an event or a drive breakpoint
                sch.accelerations(b, self.jump_at(b.t))
            self.cur, self.trial = b, a
            a, b = self.cur, self.trial
            steps += 1
            stop, on_belt = observer(a, on_belt)
            diagnosis = self._diverged(a)
            if diagnosis:
                break
            now = time.perf_counter()
            busy += now - resumed
            yield a.t
            resumed = time.perf_counter()
        self.outcome = (a.t, diagnosis, steps, rejected)

    def _diverged(self, st: State) -> str | None:
        y = st.y
        md = self.model
        if not math.isfinite(y.sum()):  # a NaN or Inf anywhere propagates to the sum
            return f"non-finite state at t = {st.t:.6f} s"
        if st.res[K.R_MAX_D] > md.deep:
            return (
                f"deep penetration D = {st.res[K.R_MAX_D]:.4g} m > {md.deep:.4g} m "
                f"at t = {st.t:.6f} s: the solve diverged or the load passed through the fence"
            )
        speed = math.hypot(y[3], y[4])
        if speed > md.speed_limit:
            return (
                f"load speed {speed:.4g} m/s exceeds {md.speed_limit:.4g} "
                f"m/s at t = {st.t:.6f} s: runaway energy, the solve diverged"
            )
        return None


__all__ = [
    "Integrator",
    "Propagators",
    "STAGE_SORTED",
    "classify",
    "generalized_alpha_coefficients",
]
