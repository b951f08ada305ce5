"""The compiled solve (``solver.engine = compiled``): one sorting event in one Numba loop.

``kernel.solve`` runs the control loop of :class:`integrators.Integrator` (adaptive step-size
control with Milne's device, event location by Illinois regula falsi, drive breakpoints, step
halving and the divergence checks) together with the reductions of :class:`result.Observer`
(energy audit, peak N with its parabola, impacts with N_stiff, stages E1-E4, recorded series)
on flat arrays, so an accepted step costs no Python at all. Same algorithm, same answers: the
Python loop stays (``solver.engine = python``, and the soft-real-time line steps it as a
generator) and test/physics/test_engine.py checks the two agree to round-off.

This module builds the arrays, calls ``kernel.solve`` in chunks of step attempts (between them it
checks ``solver.max_wall_time``, which compiled code cannot read, and grows the output buffers),
and turns the figures into the :class:`SimulationResult` the Python loop would have produced
(through ``result.make_result``, which ``Observer.result`` calls too, so every text is the
same). A one-shot solve (``run_compiled``) reuses the arrays of the previous solve of the same
shape. Every scheme of ours (adaptive, trapezoidal, generalized_alpha) runs in it.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from . import kernel as K
from .contacts import (
    FLUSH_ANGLE,
    STAGE_E1,
    STAGE_E2,
    STAGE_E3,
    STAGE_E4,
    STAGE_ON_BELT,
    STAGE_SORTED,
)
from .result import EnergyAudit, make_result

COMPILED_METHODS = ("adaptive", "trapezoidal", "generalized_alpha")
STAGE_NAMES = (STAGE_ON_BELT, STAGE_E1, STAGE_E2, STAGE_E3, STAGE_E4, STAGE_SORTED)
_STAGE_LENGTHS = np.array([len(n) for n in STAGE_NAMES])
# the names as arrays of each string width (a recorded series takes the width of its longest)
_STAGE_BY_WIDTH = {
    w: np.array(STAGE_NAMES, dtype=f"<U{w}") for w in range(1, 1 + max(map(len, STAGE_NAMES)))
}
CHUNK = 512  # step attempts between two wall-time checks (~5-50 ms of solving)


def generalized_alpha_coefficients(rho_inf: float) -> np.ndarray:
    """(alpha_m, alpha_f, beta, gamma) of Chung and Hulbert (1993) for spectral radius rho_inf."""
    am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    af = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 - am + af
    beta = 0.25 * (1.0 - am + af) ** 2
    return np.array([am, af, beta, gamma])


def uses_compiled(sc) -> bool:
    """Whether :func:`simulate.simulate` runs this scenario with the compiled loop."""
    return sc.solver.engine == "compiled" and sc.solver.method in COMPILED_METHODS


_PROPAGATORS: dict[int, tuple] = {}  # id(omega) -> (omega, zeta, cache arrays)
_NO_MODES = (
    np.full(1, math.nan),
    np.zeros((1, 0, 2, 2)),
    np.zeros((1, 0, 2)),
    np.zeros((1, 0, 2)),
    np.zeros(1, dtype=np.int64),
)


def _propagator_cache(model):
    """The exact modal maps by step size: shared by every model of the same modal basis (the
    FEM and modes are cached per fence, ``simulate._fence_modes``, so the line, the optimiser
    and the benchmarks, which build a model per event, do not recompute the matrix exponentials
    of the step-size ladder on every event). The maps depend on (omega, zeta, h) only."""
    if model.n_modes == 0:  # a stiff fence: nothing to propagate
        return _NO_MODES
    key = id(model.omega)
    hit = _PROPAGATORS.get(key)
    if hit is not None and hit[0] is model.omega and hit[1] is model.zeta:
        return hit[2]
    m, n = model.n_modes, K.N_PROP_CACHE
    cache = (
        np.full(n, math.nan),
        np.zeros((n, m, 2, 2)),
        np.zeros((n, m, 2)),
        np.zeros((n, m, 2)),
        np.zeros(1, dtype=np.int64),
    )
    if len(_PROPAGATORS) >= 16:
        _PROPAGATORS.pop(next(iter(_PROPAGATORS)))
    # the entry keeps omega and zeta alive, so their id cannot be reused while it is here
    _PROPAGATORS[key] = (model.omega, model.zeta, cache)
    return cache


_UP, _DOWN = 2.0**0.25, 2.0**-0.25  # the adaptive step's ladder rungs
_CFG_ORDER = (
    "G_H_NOM G_T_END G_DT G_MIN_DT G_TOL G_MAX_ITER G_ATOL G_RTOL G_V_REF G_OM_REF G_WIDTH "
    "G_ADAPTIVE G_STOP_SORTED G_RECORD G_BP G_KP G_DEEP G_SPEED_LIMIT G_VMIN G_PHIDOT_MIN G_UP "
    "G_DOWN G_FLUSH G_GEN_ALPHA G_ALPHA_M G_ALPHA_F G_BETA G_GAMMA"
).split()
assert [getattr(K, g) for g in _CFG_ORDER] == list(range(K.N_CFG)), "CompiledSolve's cfg order"
# the control integers and figures at the start of a solve
_CTL0 = np.zeros(K.N_CTL, dtype=np.int64)
_CTL0[K.I_TRIAL] = _CTL0[K.I_ON_BELT] = _CTL0[K.I_FIRST] = 1
_CTL0[[K.I_MASK, K.I_STAGE, K.I_LAST_MASK0, K.I_LAST_MASK1]] = -1
_FC0 = np.zeros(K.N_FC)
_FC0[[K.F_EXIT_SPEED, K.F_IMPACT_SPEED, K.F_FLOW, K.F_E0]] = math.nan
_FC0[K.F_Y_MAX] = -math.inf

# per (n_state, modes, elements): the arrays of finished solves, reused by the next one (an
# event of the optimiser, the line or the benchmark builds ~20 small arrays otherwise: ~6 us
# of NumPy calls, ~15 us on a cold cache, per ~0.3 ms stiff event)
_WORKSPACES: dict[tuple, list[tuple]] = {}


def _workspace(n: int, m: int, n_el: int, trace: int) -> tuple:
    """The arrays of one compiled solve, in the order ``CompiledSolve`` unpacks them."""
    s = K.N_STATES
    return (
        np.zeros(K.N_CTL, dtype=np.int64),
        np.zeros(K.N_FC),
        np.zeros(s),
        np.zeros((s, n)),
        np.zeros((s, 3)),
        np.zeros((s, K.N_SLOTS, K.N_COLS)),
        np.zeros((s, K.N_RES)),
        np.zeros((s, m)),
        np.zeros((s, 3 + m)),
        np.zeros(max(2 * n_el, 2)),
        np.zeros(max(2 * n_el, 2)),
        np.zeros((n_el + 1, 2)),
        np.zeros(K.N_SLOTS),
        np.zeros(K.trapezoidal_work_shape(m)),
        np.zeros((8, 3)),
        np.zeros((16, 2)),
        np.zeros((trace, K.trace_width(n, m))),
    )


class CompiledSolve:
    """The arrays of one compiled solve and its chunked driver."""

    def __init__(self, model, trace: int = 0):
        """``trace`` > 0: keep every observed point, ``trace`` at a time, for a Python observer
        (:meth:`run_ahead`, :meth:`load`)."""
        self.model = model
        sc = model.sc
        sv = sc.solver
        adaptive = sv.method == "adaptive"
        h_nom = sv.dt_max if adaptive else sv.dt
        t_cycle = 2.0 * sc.drive.t1
        self.t_end = t_end = sv.t_end if sv.t_end > 0 else t_cycle + sv.settle_time
        t1 = sc.drive.t1
        breaks = [b for b in ((t1, t_cycle) if t1 < t_cycle else (t_cycle,)) if 0.0 < b < t_end]
        breaks.append(t_end)
        self.breaks = np.array(breaks, dtype=float)
        body = model.body
        contact = sc.contact
        v_ref = max(model.belt, 0.1)
        # one list in the order of the G_* indices (checked at import), one array
        self.cfg = np.array(
            [
                h_nom,
                t_end,
                sv.dt,
                sv.min_dt,
                sv.tolerance,
                sv.max_iterations,
                sv.atol,
                sv.rtol,
                v_ref,
                v_ref / min(body.length_a, body.width_b),
                sc.conveyor.width,
                float(adaptive),
                float(sv.stop_when_sorted),
                float(bool(sc.record)),
                contact.b_p,
                contact.k_p,
                model.deep,
                model.speed_limit,
                contact.v_min,
                contact.phidot_min,
                _UP,
                _DOWN,
                FLUSH_ANGLE,
                float(sv.method == "generalized_alpha"),
                *generalized_alpha_coefficients(sv.rho_inf),
            ],
            dtype=float,
        )
        n, m = model.n_state, model.n_modes
        self._key = (n, m, model.n_el) if trace == 0 else None
        pool = _WORKSPACES.get(self._key)
        arrays = pool.pop() if pool else None  # (list.pop: atomic under the GIL)
        if arrays is None:
            arrays = _workspace(n, m, model.n_el, trace)
        (
            self.ctl, self.fc, self.T, self.Y, self.LAM, self.OUT, self.RES, self.MODAL,
            self.ACC, self.w, self.wdot, self.nodes, self.prev, self.work, self.IMP, self.STG,
            self.TR,
        ) = arrays  # fmt: skip
        # kernel.solve zeroes the other state rows and the scratch arrays on its first call
        ctl = self.ctl
        ctl[:] = _CTL0
        self.fc[:] = _FC0
        y0 = self.Y[0]
        y0.fill(0.0)
        y0[:3] = model.initial
        v = sc.initial_velocity
        y0[3:6] = v if v is not None else (model.belt, 0.0, 0.0)
        self.PK, self.PA, self.PG0, self.PG1, n_props = _propagator_cache(model)
        self._n_props = n_props
        ctl[K.I_N_PROPS] = n_props[0]
        # a column per accepted point when anything is recorded (one otherwise: none is written);
        # not reused: the result's series are views of it
        cols = int(1.5 * t_end / h_nom) + 64 if sc.record else 1
        self.REC = np.zeros((K.N_REC_COLS, min(cols, 1 << 16)))
        # the modal basis of a flexible fence is read-only (cached per fence): writable copies
        # keep one signature of kernel.solve for stiff and flexible models (one compiled
        # specialisation to load from Numba's cache per process, ~0.3 s, instead of two)
        modes = (model.phi, model.rigid_modal, model.omega, model.zeta)
        if model.flexible:
            modes = tuple(a if a.flags.writeable else a.copy() for a in modes)
        self.modes = modes
        self.busy = 0.0
        self.diagnosis: str | None = None

    @property
    def done(self) -> bool:
        return bool(self.ctl[K.I_DONE]) or self.diagnosis is not None

    @property
    def t(self) -> float:
        return float(self.T[self.ctl[K.I_CUR]])

    def _grow(self) -> None:
        for name in ("IMP", "STG"):
            arr = getattr(self, name)
            used = self.ctl[K.I_N_IMPACTS if name == "IMP" else K.I_N_STAGES]
            if used >= arr.shape[0]:
                bigger = np.zeros((2 * arr.shape[0], arr.shape[1]))
                bigger[:used] = arr[:used]
                setattr(self, name, bigger)
        used = self.ctl[K.I_N_REC]
        if used >= self.REC.shape[1]:
            bigger = np.zeros((self.REC.shape[0], 2 * self.REC.shape[1]))
            bigger[:, :used] = self.REC[:, :used]
            self.REC = bigger

    def release(self) -> None:
        """Hand the arrays back for the next solve of the same shape (``run_compiled``, once it
        has copied out everything it returns; nothing may use this solve afterwards)."""
        if self._key is None:
            return
        pool = _WORKSPACES.setdefault(self._key, [])
        if len(pool) < 4:
            pool.append(
                (
                    self.ctl, self.fc, self.T, self.Y, self.LAM, self.OUT, self.RES, self.MODAL,
                    self.ACC, self.w, self.wdot, self.nodes, self.prev, self.work, self.IMP,
                    self.STG, self.TR,
                )
            )  # fmt: skip
        self._key = None

    def _call(self, t_target: float) -> int:
        """One call of ``kernel.solve`` (at most CHUNK step attempts); grows a full buffer."""
        md = self.model
        model = K.LoopModel(md.P, md.corners, md.normals, *self.modes, self.cfg, self.breaks)
        state = K.LoopState(
            self.ctl, self.fc, self.T, self.Y, self.LAM, self.OUT, self.RES, self.MODAL,
            self.ACC, self.w, self.wdot, self.nodes, self.prev, self.work, self.PK, self.PA,
            self.PG0, self.PG1, self.IMP, self.STG, self.REC, self.TR,
        )  # fmt: skip
        status = K.solve(model, state, CHUNK, float(t_target))
        self._n_props[0] = self.ctl[K.I_N_PROPS]
        if status == K.SOLVE_GROW:
            self._grow()
        return status

    def advance(self, t_target: float = math.inf) -> bool:
        """Solve until the accepted time reaches ``t_target`` (or the end); False once the
        solve has ended. ``solver.max_wall_time`` bounds the time spent in here, summed over
        calls (as ``Integrator.advance``)."""
        limit = self.model.sc.solver.max_wall_time
        while not self.done:
            t0 = time.perf_counter()
            status = self._call(t_target)
            self.busy += time.perf_counter() - t0
            if status == K.SOLVE_REACHED:
                return True
            if not self.done and self.busy > limit:
                self.diagnosis = f"wall-time limit {limit:g} s reached at t = {self.t:.4f} s"
        return False

    def run_ahead(self) -> int:
        """Solve on until the trace is full, the solve has ended or CHUNK attempts were made;
        the number of traced points (see :meth:`load`). The caller checks the wall time."""
        while not self.done:
            if self._call(math.inf) != K.SOLVE_GROW:
                break
        return int(self.ctl[K.I_N_TRACE])

    @property
    def diverged_last(self) -> bool:
        """The solve ended on a divergence found at its last accepted (and traced) point."""
        return int(self.ctl[K.I_DIAG]) in (K.DIAG_NONFINITE, K.DIAG_DEEP, K.DIAG_SPEED)

    def load(self, k: int, st) -> bool:
        """Trace row k into an ``integrators.State``; the on_belt flag it was observed with."""
        row = self.TR[k]
        n, m = self.model.n_state, self.model.n_modes
        st.t = float(row[K.TR_T])
        i = K.TR_Y
        st.y[:] = row[i : i + n]
        i += n
        st.lam[:] = row[i : i + 3]
        i += 3
        size = K.N_SLOTS * K.N_COLS
        st.out[:] = row[i : i + size].reshape(K.N_SLOTS, K.N_COLS)
        i += size
        st.res[:] = row[i : i + K.N_RES]
        i += K.N_RES
        st.modal[:] = row[i : i + m]
        i += m
        st.acc[:] = row[i : i + 3 + m]
        return row[K.TR_ON_BELT] != 0.0

    def clear_trace(self) -> None:
        self.ctl[K.I_N_TRACE] = 0

    def outcome(self) -> tuple[float, str | None, int, int]:
        """(t, diagnosis, steps, rejected) as ``Integrator.outcome``."""
        ctl = self.ctl
        return (
            self.t,
            self.diagnosis or self._diagnosis(),
            int(ctl[K.I_STEPS]),
            int(ctl[K.I_REJECTED]),
        )

    def _diagnosis(self) -> str | None:
        """The text of ``Integrator`` for the loop's DIAG_* code."""
        code = int(self.ctl[K.I_DIAG])
        md, sv = self.model, self.model.sc.solver
        t, v = self.fc[K.F_DIAG_T], self.fc[K.F_DIAG_V]
        if code == K.DIAG_NONE:
            return None
        if code == K.DIAG_MIN_DT:
            return (
                f"step size fell below solver.min_dt={sv.min_dt:g} s at t = {t:.6f} s: "
                "the contact iteration does not converge (contact too stiff for the step?)"
            )
        if code == K.DIAG_NONFINITE:
            return f"non-finite state at t = {t:.6f} s"
        if code == K.DIAG_DEEP:
            return (
                f"deep penetration D = {v:.4g} m > {md.deep:.4g} m "
                f"at t = {t:.6f} s: the solve diverged or the load passed through the fence"
            )
        return (
            f"load speed {v:.4g} m/s exceeds {md.speed_limit:.4g} "
            f"m/s at t = {t:.6f} s: runaway energy, the solve diverged"
        )

    def _stages(self, ctl) -> list[tuple[str, float]]:
        return [(STAGE_NAMES[int(c)], t) for t, c in self.STG[: ctl[K.I_N_STAGES]].tolist()]

    def _audit(self, fc, audit) -> None:
        audit.max_residual, audit.min_residual = fc[K.F_MAX_RES], fc[K.F_MIN_RES]
        audit.flow, audit.e0 = fc[K.F_FLOW], fc[K.F_E0]
        audit.t_max, audit.t_min = fc[K.F_T_MAX], fc[K.F_T_MIN]
        audit.max_rise = fc[K.F_MAX_RISE]
        audit.t_rise = (fc[K.F_T_RISE0], fc[K.F_T_RISE1])
        audit.run_min, audit.t_run_min = fc[K.F_RUN_MIN], fc[K.F_T_RUN_MIN]

    def fill(self, obs) -> None:
        """Copy the loop's reductions into a ``result.Observer`` (for ``Observer.result``)."""
        ctl, fc = self.ctl.tolist(), self.fc.tolist()  # Python numbers, read once each
        obs.sorted = bool(ctl[K.I_SORTED])
        obs.touched = bool(ctl[K.I_TOUCHED])
        obs.had_fence = bool(ctl[K.I_HAD_FENCE])
        obs.exit_speed = fc[K.F_EXIT_SPEED]
        obs.impact_speed = fc[K.F_IMPACT_SPEED]
        obs.impacts = [(t, w, p) for t, w, p in self.IMP[: ctl[K.I_N_IMPACTS]].tolist()]
        obs.peak_n = fc[K.F_PEAK_N]
        obs.peak_tip = fc[K.F_PEAK_TIP]
        obs.max_depth = fc[K.F_MAX_DEPTH]
        obs.y_max = fc[K.F_Y_MAX]
        stages = self._stages(ctl)
        obs.stages = stages
        obs.stage = stages[-1][0] if stages else None
        self._audit(fc, obs.audit)
        obs.rec = self.series(obs.want, stages)

    def result(self, wall0: float):
        """The ``SimulationResult`` of the finished solve: ``Observer.result`` of :meth:`fill`
        without the observer (``result.make_result`` on the loop's figures); ``wall0``: the
        ``time.perf_counter()`` the run started at."""
        ctl, fc = self.ctl.tolist(), self.fc.tolist()  # Python numbers, read once each
        stages = self._stages(ctl)
        audit = EnergyAudit(
            max_residual=fc[K.F_MAX_RES],
            min_residual=fc[K.F_MIN_RES],
            flow=fc[K.F_FLOW],
            e0=fc[K.F_E0],
            t_max=fc[K.F_T_MAX],
            t_min=fc[K.F_T_MIN],
            max_rise=fc[K.F_MAX_RISE],
            t_rise=(fc[K.F_T_RISE0], fc[K.F_T_RISE1]),
            run_min=fc[K.F_RUN_MIN],
            t_run_min=fc[K.F_T_RUN_MIN],
        )
        md = self.model
        diagnosis = self.diagnosis or (None if ctl[K.I_DIAG] == K.DIAG_NONE else self._diagnosis())
        return make_result(
            md, float(self.T[ctl[K.I_CUR]]), diagnosis, ctl[K.I_STEPS], ctl[K.I_REJECTED],
            time.perf_counter() - wall0, ctl[K.I_FORCED], ctl[K.I_EVENTS],
            sorted_=bool(ctl[K.I_SORTED]), touched=bool(ctl[K.I_TOUCHED]),
            exit_speed=fc[K.F_EXIT_SPEED], impact_speed=fc[K.F_IMPACT_SPEED],
            impacts=[(t, w, p) for t, w, p in self.IMP[: ctl[K.I_N_IMPACTS]].tolist()],
            peak_n=fc[K.F_PEAK_N], peak_tip=fc[K.F_PEAK_TIP], max_depth=fc[K.F_MAX_DEPTH],
            y_max=fc[K.F_Y_MAX], stages=stages, audit=audit,
            series=self.series(md.sc.record, stages),
        )  # fmt: skip

    def series(self, want, stages=None) -> dict[str, np.ndarray]:
        """The recorded series, keyed as ``Observer._record`` keys them (each its own array: a
        row of the loop's REC, which records the time once per group); ``stages``: the run's
        stage list, if known (the recorded stage names are the names in it)."""
        if not want:
            return {}
        cols = self.REC[:, : self.ctl[K.I_N_REC]]  # one row per recorded quantity, contiguous
        out: dict[str, np.ndarray] = {}
        if "trajectory" in want:
            out["t"] = cols[K.REC_T]
            for k, key in enumerate(("x", "y", "phi", "vx", "vy", "phidot")):
                out[key] = cols[K.REC_Y + k]
        if "fence" in want:
            out["t_fence"] = cols[K.REC_T_FENCE]
            out["alpha_w"] = cols[K.REC_ALPHA]
            out["tip_deflection"] = cols[K.REC_TIP_W]
        if "forces" in want:
            out["t_forces"] = cols[K.REC_T_FORCES]
            out["normal_force"] = cols[K.REC_FENCE_N]
            out["deformation"] = cols[K.REC_MAX_D]
        if "stages" in want:
            out["t_stage"] = cols[K.REC_T_STAGE]
            codes = cols[K.REC_STAGE].astype(np.intp)
            # the dtype np.asarray gives the Python loop's list of names: the longest present
            # (every stage the run entered was recorded at the point it was entered)
            if not len(codes):
                width = 1
            elif stages:
                width = max(len(name) for name, _ in stages)
            else:
                width = int(_STAGE_LENGTHS[codes].max())
            out["stage"] = _STAGE_BY_WIDTH[width][codes]
        return out


def run_compiled(model):
    """:func:`simulate.simulate` with the compiled loop: the same ``SimulationResult``."""
    wall0 = time.perf_counter()
    solve = CompiledSolve(model)
    solve.advance()
    result = solve.result(wall0)
    solve.release()
    return result


@contextmanager
def collector_off() -> Iterator[None]:
    """The garbage collector off for a timed call (as ``timeit`` does) and back in its previous
    state after it, also when the call raises. A collection belongs before a block of timed
    calls, not before each: it walks every live object and leaves the CPU caches cold."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
