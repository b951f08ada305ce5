"""The solve loop (:func:`solve`): the one loop of every scheme (adaptive, trapezoidal,
generalized-alpha): step size, events, drive breakpoints; each accepted point goes to the
observer (``observe``: the run's reductions and divergence checks)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .control import (
    EVENT_ONSET,
    EVENT_SLIDE_OFF,
    event_value,
    first_event,
    flexible_contact_step,
    milne_error,
    modal_propagators,
    oscillation_step,
    resolves_stick,
    time_to_contact,
    tolerance_scale,
)
from .forces import evaluate, karnopp_belt, stick_wrench
from .layout import (
    DIAG_MIN_DT,
    DIAG_NONE,
    N_SLOTS,
    Evaluation,
    Row,
    Rows,
)
from .observer import diverged, observe
from .steps import (
    STEP_FORCED,
    STEP_REJECTED,
    generalized_alpha_step,
    trapezoidal_step,
)

# -- the solve loop -------------------------------------------------------------------------------
# One compiled loop over flat arrays; ``stepper.Stepper`` builds the arrays, calls :func:`solve`
# one accepted step or a chunk of attempts at a time (wall-time limit, growing the output
# buffers) and turns the figures into a ``SimulationResult``. The package's cache directory is
# keyed on all of its sources (``kernel.cache_directory``), so the loop's cached code goes with
# the kernels it inlines. NUMBA_DISABLE_JIT=1 runs the same source as Python (the reference,
# test/physics/test_jit_reference.py).

EVENT_TOL = 1e-10  # a located onset's step ends with 0 < D <= EVENT_TOL [m]
EVENT_SORT = 3  # C_s crossing the sorting line y0 = s (belt friction ends there)
SOLVE_DONE = 0
SOLVE_PAUSED = 1  # attempt budget used up (the caller checks the wall-time limit)
SOLVE_GROW = 2  # an output buffer is full
SOLVE_REACHED = 3  # the accepted time reached t_target


@njit(cache=True, _nrt=True, inline="always")
def _row(state, i):
    """The :data:`Row` of views of row i of the loop state's arrays."""
    s = state
    return Row(
        s.times[i : i + 1], s.states[i], s.accelerations[i], s.belt_wrench[i], s.contacts[i],
        s.resultants[i], s.modal_forces[i],
    )  # fmt: skip


@njit(cache=True, _nrt=True, inline="always")
def loop_rows(state):
    """The loop's state rows by role (:data:`Rows`), views of ``state``'s arrays built once per
    solve call. Inlined into its callers, it compiles with their flags (views of arguments need
    no reference counting inside compiled code); called from Python it needs Numba's reference
    counting to hand Python the views (without it the whole arrays come back), whose record
    fields Python reads by key (``row.resultant[0]["fx"]``), Numba's boxing dropping NumPy's
    ``np.record`` type."""
    return Rows(
        (_row(state, 0), _row(state, 1)), _row(state, 2), _row(state, 3), _row(state, 4),
        _row(state, 5),
    )  # fmt: skip


@njit(cache=True, _nrt=False)
def _copy_row(dst, src):
    """Copy state row src (time, state, accelerations, forces, contacts) into row dst."""
    dst.time[0] = src.time[0]
    for k in range(src.state.shape[0]):
        dst.state[k] = src.state[k]
    for k in range(3):
        dst.belt[k] = src.belt[k]
    for k in range(N_SLOTS):
        dst.contacts[k] = src.contacts[k]
    dst.resultant[0] = src.resultant[0]
    for k in range(src.modal.shape[0]):
        dst.modal[k] = src.modal[k]
    for k in range(src.acceleration.shape[0]):
        dst.acceleration[k] = src.acceleration[k]


@njit(cache=True, _nrt=True, inline="always")
def _evaluation(state, row):
    """The :data:`Evaluation` of a state row (its contacts, resultant, modal force and belt
    wrench, with the shared scratch arrays)."""
    s = state
    return Evaluation(
        row.contacts, row.resultant, row.modal, s.deflection, s.deflection_rate, s.nodes,
        s.friction_prev, row.belt,
    )  # fmt: skip


@njit(cache=True, _nrt=False)
def _propagator_slot(model, state, h):
    """Row of the exact modal maps for step h in the cache (computed on a miss; the cache is
    emptied when full)."""
    omega, counters, keys = model.omega, state.counters, state.propagator_keys
    if omega.shape[0] == 0:
        return 0
    n = counters[0].n_props
    for i in range(n):
        if keys[i] == h:
            return i
    if n >= keys.shape[0]:
        n = 0
    modal_propagators(
        omega, model.zeta, h, state.propagators[n], state.propagator_g0[n], state.propagator_g1[n]
    )
    keys[n] = h
    counters[0].n_props = n + 1
    return n


@njit(cache=True, _nrt=False)
def _jump_at(params, t):
    if abs(t - 2.0 * params[0].t1) <= 1e-12:
        return -0.5 * params[0].alpha_k * (math.pi / params[0].t1) ** 2
    return 0.0


@njit(cache=True, _nrt=False)
def _snap(h_nom, h):
    """Round an adaptive step down onto the ladder dt_max 2^(-k/4), so the exact modal
    propagators (a matrix exponential per mode) are reused instead of recomputed."""
    if h == h_nom:  # k = 0 (most steps: no log2 and pow calls)
        return h_nom
    k = math.ceil(4.0 * math.log2(h_nom / h) - 1e-9)
    return h_nom * 2.0 ** (-k / 4.0)


@njit(cache=True, _nrt=False, inline="always")
def _load_accelerations(params, row):
    """The load's accelerations of a state row from its contact resultant and belt wrench."""
    res, belt, acc = row.resultant[0], row.belt, row.acceleration
    acc[0] = (res.fx + belt[0]) / params[0].mass
    acc[1] = (res.fy + belt[1]) / params[0].mass
    acc[2] = (res.mz + belt[2]) / params[0].inertia


@njit(cache=True, _nrt=False)
def _trap(model, state, h, h_prev, start, end, previous, jump, on_belt, force):
    """One trapezoidal step from state row ``start`` into row ``end`` (exact modal maps for
    step h; ``h_prev``: the step before start, 0 without history; ``previous``: the modal force
    at the accepted point before start)."""
    s = state
    k = _propagator_slot(model, state, h)
    props = (s.propagators[k], s.propagator_g0[k], s.propagator_g1[k])
    status = trapezoidal_step(
        model, props, h, h_prev, start.time[0], start.state, _evaluation(state, start), previous,
        jump, on_belt, force, end.state, _evaluation(state, end), s.work,
    )  # fmt: skip
    if status != STEP_REJECTED:
        _load_accelerations(model.params, end)
    end.time[0] = start.time[0] + h
    return status


@njit(cache=True, _nrt=False)
def _alpha(model, state, h, start, end, alpha, on_belt, force):
    """One generalized-alpha step from state row ``start`` into row ``end`` (``alpha``: the
    state at the step's alpha point, scratch; ``settings[0].gen_alpha``; the loop calls it
    where the other schemes call :func:`_trap`)."""
    status = generalized_alpha_step(
        model, h, start.time[0], start.state, start.acceleration, _evaluation(state, start),
        on_belt, force, end.state, end.acceleration, _evaluation(state, end), alpha,
    )  # fmt: skip
    end.time[0] = start.time[0] + h
    return status


@njit(cache=True, _nrt=False, inline="always")
def _attempt(model, state, rows, h, h_hist, start, end, on_belt, force):
    """One step of the event's scheme from state row ``start`` into row ``end`` (of ``rows``):
    generalized-alpha (``settings[0].gen_alpha``) or trapezoidal (``h_hist``: the step before
    start, 0 without history); returns its status."""
    if model.settings[0].gen_alpha != 0.0:
        return _alpha(model, state, h, start, end, rows.alpha.state, on_belt, force)
    jump = _jump_at(model.params, start.time[0])
    return _trap(model, state, h, h_hist, start, end, rows.previous.modal, jump, on_belt, force)


@njit(cache=True, _nrt=False)
def _accelerations(model, row, jump):
    """Accelerations of a state row consistent with its forces (the start, and
    generalized-alpha's restart after an event or a drive breakpoint; ``jump``: the drive's
    acceleration jump at 2 t1, which the forces at the breakpoint do not contain yet)."""
    rigid_modal, omega, zeta = model.rigid_modal, model.omega, model.zeta
    modal, acc, y = row.modal, row.acceleration, row.state
    m = omega.shape[0]
    _load_accelerations(model.params, row)
    for j in range(m):
        acc[3 + j] = (
            modal[j]
            - rigid_modal[j] * jump
            - omega[j] ** 2 * y[6 + j]
            - 2.0 * zeta[j] * omega[j] * y[6 + m + j]
        )


@njit(cache=True, _nrt=False)
def _initial_belt(params, settings, row):
    """The belt wrench of the initial state row from its resultant: Karnopp's, or the stick
    wrench when the load rides at belt speed."""
    y, r, belt = row.state, row.resultant, row.belt
    bx, by, bz = karnopp_belt(params, y[3] - params[0].belt, y[4], y[5], r[0].fx, r[0].fy, r[0].mz)
    belt[0], belt[1], belt[2] = bx, by, bz
    if (
        math.hypot(y[3] - params[0].belt, y[4]) <= settings[0].v_min
        and abs(y[5]) <= settings[0].phidot_min
    ):
        bx, by, bz = stick_wrench(params, r[0].fx, r[0].fy, r[0].mz)
        belt[0], belt[1], belt[2] = bx, by, bz


@njit(cache=True, _nrt=False)
def _locate(model, state, rows, start, end, h, h_prev, on_belt, slot, kind, g0, g1):
    """Shorten the step to end just past the sign change of ``slot``'s event function (or the
    sort crossing): Illinois regula falsi until an onset step ends within EVENT_TOL of D = 0
    (so w_n is read at the onset), a slide-off or sort crossing step ends within the iteration
    tolerance of its line, or the bracket is below 1e-7 of the step. A corner sliding off the
    tip ends one step just before the slide-off (the force there is the peak the step would
    otherwise skip) and the next just past it. Steps from row ``start``; the located trial is
    left in row ``end`` (the trial row); returns the step taken."""
    params, settings, counters = model.params, model.settings, state.counters
    located, before = rows.located, rows.before
    onset = kind == EVENT_ONSET
    sign0 = g0 > 0.0
    lo = 0.0
    hi, g_hi = h, g1
    best = 0.0
    have_best = False
    tol = settings[0].tol
    keep_before = kind == EVENT_SLIDE_OFF and g0 > tol
    cross = kind == EVENT_SLIDE_OFF and not keep_before
    sort = kind == EVENT_SORT
    g_lo = g0
    h_before = 0.0
    have_before = False
    f_lo, f_hi, last = g0, g1, 0
    lo_prev, g_lo_prev = 0.0, g0  # the lo end before the last (the secant on the smooth side)
    for _ in range(60):
        if hi - lo <= 1e-7 * h or (onset and g_hi <= EVENT_TOL):
            break
        if (have_before and g_lo <= tol) or ((cross or sort) and have_best and -g_hi <= tol):
            break
        h_loc = lo + (hi - lo) * (f_lo / (f_lo - f_hi))
        if cross and last == 0:
            h_loc = min(2.0 * h_loc, hi)  # the tip is within tol: step just past it
        else:
            h_loc = min(max(h_loc, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
        if keep_before and last == -1 and g_lo_prev > g_lo:
            h_sec = lo + (g_lo - 0.5 * tol) * (lo - lo_prev) / (g_lo_prev - g_lo)
            if lo < h_sec < hi:
                h_loc = h_sec
        st = _attempt(model, state, rows, h_loc, h_prev, start, located, on_belt, False)
        if st == STEP_REJECTED:
            break
        if kind == EVENT_SORT:
            g = settings[0].width - located.state[1]
        else:
            g = event_value(params, located.contacts, slot, kind)
        if math.isnan(g):
            break
        if (g > 0.0) != sign0:
            hi, g_hi, f_hi = h_loc, g, g
            if last == 1:
                f_lo *= 0.5
            last = 1
            best = h_loc
            have_best = True
            _copy_row(end, located)
        else:
            lo_prev, g_lo_prev = lo, g_lo
            lo, g_lo, f_lo = h_loc, g, g
            if last == -1:
                f_hi *= 0.5
            last = -1
            if keep_before:
                h_before = h_loc
                have_before = True
                _copy_row(before, located)
    counters[0].n_events += 1
    if have_before:
        _copy_row(end, before)
        return h_before
    return best if have_best else h


@njit(cache=True, _nrt=False, inline="always")
def _observe(model, state, i, on_belt):
    """Observe accepted state row i (``observer.observe``, the run's reductions); whether to
    stop and whether the load is on the belt go to the counters."""
    s = state
    stop, on_belt = observe(
        model.params, model.normals, model.settings, s.counters, s.figures, s.times, s.states,
        s.belt_wrench, s.contacts, s.resultants, s.impacts, s.stages, s.record, i, on_belt,
    )  # fmt: skip
    s.counters[0].stop = 1 if stop else 0
    s.counters[0].on_belt = 1 if on_belt else 0


@njit(cache=True, _nrt=False)
def solve(model, state, max_attempts, t_target):
    """Run the solve loop on ``model`` (:data:`LoopModel`) from where ``state``
    (:data:`LoopState`) left it: until it ends (SOLVE_DONE, the diagnosis in counters[0].diag),
    ``max_attempts`` step attempts (SOLVE_PAUSED; 1: at most one accepted step), an output
    buffer (impacts, stages rows; recorded points) without a
    free entry (SOLVE_GROW) or the accepted time reaching ``t_target`` (SOLVE_REACHED). The
    state rows are named (``rows``, :func:`loop_rows`); the accepted one,
    ``rows.trial[counters[0].cur]``, holds the initial state on the first call, which zeroes
    the other state rows and the scratch arrays, evaluates the forces there and observes it
    (``max_attempts`` 0: only that)."""
    (
        params, corners, normals, mode_shapes, rigid_modal, omega, zeta, settings, breakpoints,
    ) = model  # fmt: skip
    (
        counters, figures, times, states, belt_wrench, contacts, resultants, modal_forces,
        accelerations, deflection, deflection_rate, nodes, friction_prev, work, propagator_keys,
        propagators, propagator_g0, propagator_g1, impacts, stages, record,
    ) = state  # fmt: skip
    adaptive = settings[0].adaptive != 0.0
    h_nom = settings[0].h_nom
    min_dt = settings[0].min_dt
    width = settings[0].width
    m = omega.shape[0]
    # tolerance proportionality (and on a flexible fence the contact's step and the event
    # restart: the modes' error, which Milne's estimate on the load does not see); below the
    # default rtol a stiff fence's stick is resolved (control.resolves_stick)
    tol_scale = tolerance_scale(settings[0].rtol)
    friction_events = resolves_stick(settings, m)
    rows = loop_rows(state)
    if counters[0].started == 0:
        # forces at t = 0, belt wrench by Karnopp, consistent accelerations
        counters[0].started = 1
        a = counters[0].cur
        # the state rows other than the initial state, and the scratch arrays, start at zero
        # (the caller may pass arrays of an earlier solve: the stepper reuses them)
        times[:] = 0.0
        for i in range(states.shape[0]):
            if i != a:
                states[i, :] = 0.0
        belt_wrench[:, :] = 0.0
        contacts.view(np.float64)[:, :] = 0.0
        resultants.view(np.float64)[:, :] = 0.0
        modal_forces[:, :] = 0.0
        accelerations[:, :] = 0.0
        deflection[:] = 0.0
        deflection_rate[:] = 0.0
        nodes[:, :] = 0.0
        work[:, :] = 0.0
        for k in range(N_SLOTS):
            friction_prev[k] = math.nan
        cur = rows.trial[a]
        evaluate(model, cur.time[0], 0.0, cur.state, cur.belt, 0.0, _evaluation(state, cur))
        _initial_belt(params, settings, cur)
        _accelerations(model, cur, 0.0)
        _observe(model, state, a, True)
        figures[0].h = h_nom if not adaptive else min(h_nom, settings[0].dt)
        figures[0].h_cap = h_nom
        figures[0].h_prev = 0.0
    attempts = 0
    while True:
        a = counters[0].cur
        b = counters[0].trial
        cur, trial = rows.trial[a], rows.trial[b]
        t = cur.time[0]
        if counters[0].stop != 0 or not t < settings[0].t_end - 1e-12:
            counters[0].done = 1
            return SOLVE_DONE
        if t >= t_target - 1e-12:
            return SOLVE_REACHED
        if attempts >= max_attempts:
            return SOLVE_PAUSED
        if (
            counters[0].n_impacts >= impacts.shape[0]
            or counters[0].n_stages >= stages.shape[0]
            or counters[0].n_rec >= record.shape[0]
        ):
            return SOLVE_GROW
        attempts += 1
        on_belt = counters[0].on_belt != 0
        nb = counters[0].next_break
        while breakpoints[nb] <= t + 1e-12:
            nb += 1
        counters[0].next_break = nb
        to_break = breakpoints[nb] - t
        h_try = min(figures[0].h, to_break)
        if adaptive:
            cap = min(
                time_to_contact(cur.contacts),
                oscillation_step(params, cur.contacts, settings[0].rtol),
            )
            if m > 0:
                cap = min(cap, flexible_contact_step(cur.contacts, h_nom, tol_scale))
            h_try = min(h_try, max(cap, 10.0 * min_dt))
            tiny = h_try <= 4.0 * min_dt
        else:
            tiny = h_try <= 1e-3 * h_nom
        # the modes' force is quadratic through the previous point (adaptive)
        h_hist = figures[0].h_prev if adaptive else 0.0
        status = _attempt(model, state, rows, h_try, h_hist, cur, trial, on_belt, tiny)
        if status == STEP_REJECTED:
            counters[0].n_rejected += 1
            figures[0].h = h_try / 2.0
            figures[0].h_cap = h_try * settings[0].down
            counters[0].clean = 0
            if figures[0].h < min_dt:
                counters[0].diag = DIAG_MIN_DT
                figures[0].diag_t = t
                counters[0].done = 1
                return SOLVE_DONE
            continue
        if status == STEP_FORCED:
            counters[0].n_forced += 1
        h_taken = h_try
        slot, kind, g0, g1 = first_event(params, cur.contacts, trial.contacts, friction_events)
        y0, y1 = cur.state[1], trial.state[1]
        if slot < 0 and on_belt and y0 < width <= y1:
            slot, kind, g0, g1 = -1, EVENT_SORT, width - y0, width - y1
        located = False
        if (slot >= 0 or kind == EVENT_SORT) and h_try > 1e-9:
            h_taken = _locate(
                model, state, rows, cur, trial, h_try, h_hist, on_belt, slot, kind, g0, g1
            )
            located = True
        if adaptive:
            h_prev = figures[0].h_prev
            r = h_taken / h_prev if h_prev > 0.0 else 0.0
            err = milne_error(
                cur.state, cur.acceleration, trial.state, figures[0].prev_v,
                figures[0].prev_a, r, h_taken, tol_scale * settings[0].atol,
                tol_scale * settings[0].rtol, settings[0].v_ref, settings[0].om_ref,
            )  # fmt: skip
            order = 3.0 if r > 0.0 else 2.0
            if err > 1.0 and h_taken > 4.0 * min_dt:
                counters[0].n_rejected += 1
                figures[0].h = _snap(h_nom, h_taken * max(0.2, 0.9 * err ** (-1.0 / order)))
                continue
            if not located:
                counters[0].clean += 1
                if counters[0].clean >= 4 and figures[0].h_cap < h_nom:
                    figures[0].h_cap = figures[0].h_cap * settings[0].up
                    counters[0].clean = 0
                cap = min(h_nom, figures[0].h_cap)
                # h_taken grow >= cap when err <= (0.9 h_taken / cap)^order (and cap <= 4
                # h_taken); with a 1 % margin for pow's rounding that decides without the pow
                # call (most steps: at the cap with a small error); the same step otherwise
                ratio = 0.9 * h_taken / cap
                bound = ratio * ratio * ratio if order == 3.0 else ratio * ratio
                if cap <= 4.0 * h_taken and err <= 0.99 * bound:
                    h_next = cap
                else:
                    grow = min(4.0, 0.9 * max(err, 1e-12) ** (-1.0 / order))
                    h_next = min(cap, h_taken * grow)
                figures[0].h = _snap(h_nom, h_next)
            elif m > 0:
                # the error history restarts at an event and the next step's estimate (order
                # 2, the load's) is blind to a contact force rising from zero as t^2 while the
                # fence's fast modes take its rate: restart no longer than the step that met
                # the event (at an onset the approach's time_to_contact) times tol_scale
                figures[0].h = _snap(h_nom, h_try * tol_scale)
        else:
            # a fixed step regrows from a rejection's halving, not from a step the drive's
            # breakpoint cut short: after the breakpoint the grid goes on at h_nom from it, so
            # the solution is continuous in the parameters that move the grid's phase (event
            # times) as the cut step shrinks to zero, without a run of doubling steps that
            # appears or vanishes with it
            figures[0].h = min(h_nom, 2.0 * figures[0].h)
        # accept
        for k in range(3):
            figures[0].prev_v[k] = cur.state[3 + k]
            figures[0].prev_a[k] = cur.acceleration[k]
        for j in range(m):
            rows.previous.modal[j] = cur.modal[j]
        figures[0].h_prev = h_taken
        if located or abs(t + h_taken - breakpoints[nb]) <= 1e-12:
            figures[0].h_prev = 0.0
            if settings[0].gen_alpha != 0.0:
                # restart from consistent accelerations after an event or a drive breakpoint
                jump = _jump_at(params, trial.time[0])
                _accelerations(model, trial, jump)
        counters[0].cur = b
        counters[0].trial = a
        counters[0].n_steps += 1
        _observe(model, state, b, on_belt)
        diag = diverged(params, settings, figures, trial.time[0], trial.state, trial.resultant)
        if diag != DIAG_NONE:
            counters[0].diag = diag
            counters[0].done = 1
            return SOLVE_DONE
