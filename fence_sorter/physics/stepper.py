"""Stepping one sorting event through the solve loop, as scipy's ``OdeSolver`` steps an ODE:
:class:`Stepper`.

Our schemes (``solver.method``; docs/reports/accuracy/ measures each):

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

All three run in one loop, ``kernel.solve``, and share the events that would otherwise cost the
schemes their order: contact onset and release (a fence contact's law (16) crossing N = 0,
which includes the N >= 0 clamp engaging) are located by regula falsi so a step ends on them;
the drive's acceleration jumps (0, t1, 2 t1) are step ends (generalized-alpha restarts from
consistent accelerations after each); belt and fence stick/slip is implicit (exact stick, the
paper's 1e-6 m/s Karnopp window kept); C_s crossing the sorting line y0 = s ends a step (the belt
stops carrying the load there). A step whose contact iteration fails is halved; a step this
small that still fails straddles a switch and is taken and counted (forced). Divergence (NaN,
runaway speed, deep penetration, step below min_dt, wall-time limit) stops the solve with a
:class:`Diagnosis`; nothing past it is returned as data.

The loop works on flat arrays, so an accepted step costs no Python at all. A :class:`Stepper`
holds them for one :class:`~.model.SortingModel` and drives the loop: :meth:`Stepper.step` to
the next accepted point (the soft-real-time line), :meth:`Stepper.advance` to a time
(``simulate``, in chunks of step attempts: between them it checks ``solver.max_wall_time``,
which compiled code cannot read, and grows the output buffers); :meth:`Stepper.result` is the
:class:`~.result.SimulationResult` from the loop's own reductions (peaks, impacts with N_stiff,
stages, energy audit, recorded series). :meth:`Stepper.observe` feeds a point integrated
elsewhere (the SciPy baselines) to the same reductions. As MuJoCo splits a static model from
its dynamic data, the loop's model (``kernel.LoopModel``: parameters, geometry, modes, settings)
is built once per scenario and shared by its solves, and a one-shot solve (:func:`run`) hands
its loop state (``kernel.LoopState``) to the next solve of the same shape: repeated events of a
scene (the optimiser, the line, the benchmarks) pay neither again.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from enum import Enum
from functools import lru_cache
from typing import Protocol

import numpy as np

from fence_sorter.codes import Stage

from . import kernel as K
from .model import SortingModel
from .result import EnergyAudit, SimulationResult, make_result
from .scenario import RECORDABLE, Scenario, per_scenario

# the result's stage names: the labels of the Stage values (the solve loop's stage codes)
STAGE_NAMES = tuple(s.label for s in Stage)
_STAGE_LENGTHS = np.array([len(n) for n in STAGE_NAMES])
# the names as arrays of each string width (a recorded series takes the width of its longest)
_STAGE_BY_WIDTH = {
    w: np.array(STAGE_NAMES, dtype=f"<U{w}") for w in range(1, 1 + max(map(len, STAGE_NAMES)))
}
CHUNK = 512  # step attempts between two wall-time checks (~5-50 ms of solving)


class Failure(Enum):
    """Why a solve stopped short: the kind of a :class:`Diagnosis`."""

    NON_FINITE = "non_finite"
    DEEP_PENETRATION = "deep_penetration"
    RUNAWAY_SPEED = "runaway_speed"
    STEP_BELOW_MIN_DT = "step_below_min_dt"
    WALL_TIME_LIMIT = "wall_time_limit"
    SOLVER_FAILED = "solver_failed"  # a SciPy baseline's solver gave up (its message)


@dataclass(frozen=True)
class Diagnosis:
    """A failed solve: its kind, the time it was found, the value that failed (D [m], speed
    [m/s], the step [s] or the wall-time limit [s]; nan for a non-finite state) and the text
    the result and the line report."""

    kind: Failure
    t: float
    value: float
    text: str

    def __str__(self) -> str:
        return self.text


_FAILURES = {
    K.DIAG_NONFINITE: Failure.NON_FINITE,
    K.DIAG_DEEP: Failure.DEEP_PENETRATION,
    K.DIAG_SPEED: Failure.RUNAWAY_SPEED,
    K.DIAG_MIN_DT: Failure.STEP_BELOW_MIN_DT,
}


def diagnosis_text(model: SortingModel, kind: Failure, t: float, value: float) -> str:
    """The one-line text of a failure."""
    sv = model.sc.solver
    if kind is Failure.WALL_TIME_LIMIT:
        return f"wall-time limit {value:g} s reached at t = {t:.4f} s"
    if kind is Failure.STEP_BELOW_MIN_DT:
        return (
            f"step size fell below solver.min_dt={sv.min_dt:g} s at t = {t:.6f} s: "
            "the contact iteration does not converge (contact too stiff for the step?)"
        )
    if kind is Failure.NON_FINITE:
        return f"non-finite state at t = {t:.6f} s"
    if kind is Failure.DEEP_PENETRATION:
        return (
            f"deep penetration D = {value:.4g} m > {model.deep:.4g} m "
            f"at t = {t:.6f} s: the solve diverged or the load passed through the fence"
        )
    return (
        f"load speed {value:.4g} m/s exceeds {model.speed_limit:.4g} "
        f"m/s at t = {t:.6f} s: runaway energy, the solve diverged"
    )


@lru_cache(maxsize=64)
def generalized_alpha_coefficients(rho_inf: float) -> tuple[float, float, float, float]:
    """(alpha_m, alpha_f, beta, gamma) of Chung and Hulbert (1993) for spectral radius rho_inf
    (cached: a solve's settings are built per event)."""
    am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    af = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 - am + af
    beta = 0.25 * (1.0 - am + af) ** 2
    return am, af, beta, gamma


_PROPAGATORS: dict[int, tuple] = {}  # id(omega) -> (omega, zeta, cache arrays)
_NO_MODES = (
    np.full(1, math.nan),
    np.zeros((1, 0, 2, 3)),
    np.zeros((1, 0, 2)),
    np.zeros((1, 0, 2)),
    np.zeros(1, dtype=np.int64),
)


def _propagator_cache(model):
    """The exact modal maps by step size: shared by every model of the same modal basis (the
    FEM and modes are cached per fence, ``model._fence_modes``, so the line, the optimiser
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
        np.zeros((n, m, 2, 3)),
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
# the control integers and figures at the start of a solve. From Python, a record's fields are
# read and written through the array (``counters["cur"][0]``, ~0.1 us): an ``np.record``
# element's attribute costs microseconds, and assigning a whole record array goes field by
# field, so a solve's start copies the records as their flat int64 / float64 words
_CTL0 = np.zeros(1, K.COUNTERS)
for _name in ("trial", "on_belt", "first"):
    _CTL0[_name] = 1
for _name in ("mask", "stage", "last_mask0", "last_mask1"):
    _CTL0[_name] = -1
_FC0 = np.zeros(1, K.FIGURES)
for _name in ("exit_speed", "impact_speed", "flow", "e0"):
    _FC0[_name] = math.nan
_FC0["y_max"] = -math.inf
_CTL0_WORDS, _FC0_WORDS = _CTL0.view(np.int64), _FC0.view(np.float64)


def _word_of(record: np.dtype) -> dict[str, int]:
    """Each scalar field's position among the record's 8-byte words (its flat view)."""
    return {name: record.fields[name][1] // 8 for name in record.names if not record[name].shape}


_COUNTER_WORD, _FIGURE_WORD = _word_of(K.COUNTERS), _word_of(K.FIGURES)

# per (n_state, modes, elements): the loop states (``kernel.LoopState``) of finished solves,
# reused by the next one: an event of the optimiser, the line or the benchmark builds ~20
# small arrays otherwise (~6 us of NumPy calls, ~15 us on a cold cache, per ~0.2 ms stiff
# event), and ``kernel.solve.entry`` checks the types of a state it has seen only once (~7 us)
_WORKSPACES: dict[tuple, list[tuple]] = {}
_POOLED_RECORD = 1 << 12  # a state whose record grew past this many columns is not kept

# the stepper's attribute for each field of ``kernel.LoopState`` (the field's name, but the
# rows of contacts, resultants, impacts and stages, which the stepper calls ``*_rows``)
_ROWS = ("contacts", "resultants", "impacts", "stages")
_STATE_ATTRIBUTES = tuple(
    f"{name[:-1]}_rows" if name in _ROWS else name for name in K.LoopState._fields
)


def _loop_state(n: int, m: int, n_el: int, propagators: tuple, cols: int) -> tuple:
    """A ``kernel.LoopState`` for a model of n states, m modes and n_el elements, with the
    modal propagator cache ``propagators`` and a record of ``cols`` columns."""
    s = K.N_ROWS
    return K.LoopState(
        np.zeros(1, K.COUNTERS),
        np.zeros(1, K.FIGURES),
        np.zeros(s),
        np.zeros((s, n)),
        np.zeros((s, 3)),
        np.zeros((s, K.N_SLOTS), K.CONTACT),
        np.zeros((s, 1), K.RESULT),
        np.zeros((s, m)),
        np.zeros((s, 3 + m)),
        np.zeros(max(2 * n_el, 2)),
        np.zeros(max(2 * n_el, 2)),
        np.zeros((n_el + 1, 2)),
        np.zeros(K.N_SLOTS),
        np.zeros(K.trapezoidal_work_shape(m)),
        *propagators[:4],
        np.zeros((8, 3)),
        np.zeros((16, 2)),
        # a point per accepted point when anything is recorded (one otherwise: none is
        # written). Not zeroed: the loop writes every field of a point, and only the points
        # written are read
        np.empty(cols, K.RECORDED),
    )


def segments(sc: Scenario) -> tuple[float, tuple[float, ...]]:
    """The end time of a solve (``solver.t_end``, or the fence cycle 2 t1 plus
    ``solver.settle_time``) and the times every scheme ends a step on: the drive's breakpoints
    t1 and 2 t1 before the end (the drive acceleration jumps there), then the end time. The one
    definition for our schemes (:class:`Stepper`) and the SciPy baselines
    (``baselines.ScipyStepper``, which restarts its solver on each)."""
    sv = sc.solver
    t1 = sc.drive.t1
    t_cycle = 2.0 * t1
    t_end = sv.t_end if sv.t_end > 0 else t_cycle + sv.settle_time
    breaks = [b for b in ((t1, t_cycle) if t1 < t_cycle else (t_cycle,)) if 0.0 < b < t_end]
    return t_end, (*breaks, t_end)


@per_scenario
def _loop_static(sc: Scenario) -> tuple:
    """What the solve loop reads of a scenario and never writes, built once per scenario and
    shared by its solves: the ``kernel.LoopModel`` (packed parameters, the load's geometry, the
    modal basis, the settings record, the breakpoints: the drive's acceleration jumps and the
    end time), the end time, the record's first column count and the initial state. A flexible
    fence's basis is read-only (cached per fence): writable copies keep one signature of
    kernel.solve for stiff and flexible models (one compiled specialisation to load from
    Numba's cache per process, ~0.3 s, instead of two)."""
    model = SortingModel(sc)
    sv = sc.solver
    adaptive = sv.method == "adaptive"
    h_nom = sv.dt_max if adaptive else sv.dt
    t_end, breaks = segments(sc)
    body = model.body
    contact = sc.contact
    v_ref = max(model.belt, 0.1)
    # one tuple in the record's field order, one array (a field assignment each costs ~1 us)
    fields = (
        h_nom, t_end, sv.dt, sv.min_dt, sv.tolerance, sv.max_iterations, sv.atol, sv.rtol,
        v_ref, v_ref / min(body.length_a, body.width_b), sc.conveyor.width, float(adaptive),
        float(sv.stop_when_sorted), float(bool(sc.record)), contact.b_p, contact.k_p, model.deep,
        model.speed_limit, contact.v_min, contact.phidot_min, _UP, _DOWN, K.FLUSH_ANGLE,
        float(sv.method == "generalized_alpha"), generalized_alpha_coefficients(sv.rho_inf),
    )  # fmt: skip
    settings = np.array([fields], dtype=K.SETTINGS)
    cols = int(1.5 * t_end / h_nom) + 64 if sc.record else 1
    modes = (model.phi, model.rigid_modal, model.omega, model.zeta)
    if model.flexible:
        modes = tuple(a if a.flags.writeable else a.copy() for a in modes)
    breakpoints = np.array(breaks, dtype=float)
    loop_model = K.LoopModel(model.P, model.corners, model.normals, *modes, settings, breakpoints)
    return loop_model, t_end, min(cols, 1 << 16), model.initial_state()


@lru_cache(maxsize=16)
def _series_layout(want: tuple[str, ...]) -> tuple[tuple[str, str, int], ...]:
    """The series of the recorded groups ``want`` (in RECORDABLE's order): (name, field,
    element or -1) of the loop's RECORDED points (``kernel.RECORDED_SERIES``)."""
    return tuple(
        (name, field, k if len(names) > 1 else -1)
        for group in RECORDABLE
        if group in want
        for field, of, names in K.RECORDED_SERIES
        if of == group
        for k, name in enumerate(names)
    )


class Stepper:
    """One sorting event in the compiled solve loop, stepped like scipy's ``OdeSolver``.

    ``t``, ``y``: the last accepted point (the initial state before the first step);
    ``status``: ``running``, ``finished`` (the end time, or sorted with
    ``solver.stop_when_sorted``) or ``failed`` (``diagnosis`` says why; ``t`` and ``y`` are where
    the divergence was found). ``clock``: the wall clock ``solver.max_wall_time`` is measured
    on; it counts only the time spent in :meth:`step` and :meth:`advance`, not the pauses of a
    soft-real-time caller between them.
    """

    def __init__(self, model: SortingModel, clock: Callable[[], float] = time.perf_counter):
        self.model = model
        self.clock = clock
        self.wall0 = clock()
        static, self.t_end, cols, y0 = _loop_static(model.sc)
        if model.P is not static.params:  # a model whose parameters a caller changed
            static = static._replace(params=model.P)
        self.loop_model = static
        self.settings, self.breakpoints = static.settings, static.breakpoints
        n, m = model.n_state, model.n_modes
        self._key = (n, m, model.n_el)
        propagators = _propagator_cache(model)
        self._n_props = n_props = propagators[4]
        pool = _WORKSPACES.get(self._key)
        state = pool.pop() if pool else None  # (list.pop: atomic under the GIL)
        if state is None:
            state = _loop_state(n, m, model.n_el, propagators, cols)
        else:
            if state.propagators is not propagators[1]:  # another modal basis
                keys, maps, g0, g1 = propagators[:4]
                state = state._replace(
                    propagator_keys=keys, propagators=maps, propagator_g0=g0, propagator_g1=g1
                )
            if state.record.shape[0] < cols:
                state = state._replace(record=np.empty(cols, K.RECORDED))
        for name, array in zip(_STATE_ATTRIBUTES, state, strict=True):
            setattr(self, name, array)
        self._args: tuple | None = (static, state)
        self._solve = None  # the entry for ``_args`` (``kernel.solve.entry``), on first use
        # kernel.solve zeroes the other state rows and the scratch arrays on its first call
        counters = self.counters
        counters.view(np.int64)[:] = _CTL0_WORDS
        self.figures.view(np.float64)[:] = _FC0_WORDS
        self.times[0] = 0.0
        self.states[0] = y0
        counters["n_props"][0] = n_props[0]
        self.busy = 0.0
        self.status = "running"
        self.diagnosis: Diagnosis | None = None

    # -- the OdeSolver interface -------------------------------------------------------------

    @property
    def t(self) -> float:
        return float(self.times[self.counters["cur"][0]])

    @property
    def y(self) -> np.ndarray:
        """The state vector at :attr:`t` (a view: copy it to keep it)."""
        return self.states[self.counters["cur"][0]]

    @property
    def running(self) -> bool:
        return self.status == "running"

    def step(self) -> str | None:
        """Advance to the next accepted point; None, or the diagnosis text when the solve
        failed (as ``OdeSolver.step``). Raises once the solve has ended."""
        if self.status != "running":
            raise RuntimeError(f"step() on a {self.status} solve")
        steps = self.counters["n_steps"][0]
        while self.status == "running" and self.counters["n_steps"][0] == steps:
            if self._over_time():
                break
            self._call(1, math.inf)
        if self.status == "running" and self._at_end():
            self.status = "finished"
        return None if self.diagnosis is None else self.diagnosis.text

    def advance(self, t_target: float = math.inf) -> bool:
        """Solve until the accepted time reaches ``t_target`` (or the end); False once the
        solve has ended."""
        while self.status == "running":
            if self._call(CHUNK, t_target) == K.SOLVE_REACHED:
                return True
            self._over_time()
        return False

    def start(self) -> None:
        """Evaluate the forces and reductions at the initial point (the first :meth:`step` or
        :meth:`advance` does it otherwise), for a caller reading the point before stepping."""
        if not self.counters["started"][0]:
            self._call(0, math.inf)

    # -- the loop's figures at the last accepted point ----------------------------------------

    @property
    def resultants(self) -> np.ndarray:
        """The resultants (one RESULT record) at :attr:`t`."""
        return self.resultant_rows[self.counters["cur"][0]]

    @property
    def contacts(self) -> np.ndarray:
        """The contact slots (CONTACT records) at :attr:`t`."""
        return self.contact_rows[self.counters["cur"][0]]

    @property
    def stage(self) -> Stage:
        """The motion stage at :attr:`t`."""
        return Stage(int(self.counters["stage"][0]))

    @property
    def sorted(self) -> bool:
        """C_s has crossed the sorting line y0 = s."""
        return bool(self.counters["sorted"][0])

    @property
    def impacts(self) -> list[tuple[float, float, float]]:
        """(onset time [s], w_n [m/s], N_stiff [N]) of every impact so far."""
        return [
            (t, w, p) for t, w, p in self.impact_rows[: self.counters["n_impacts"][0]].tolist()
        ]

    # -- the driver --------------------------------------------------------------------------

    def _at_end(self) -> bool:
        return bool(self.counters["stop"][0]) or not self.t < self.t_end - 1e-12

    def _over_time(self) -> bool:
        """Fail the solve once the time spent stepping exceeds ``solver.max_wall_time``."""
        limit = self.model.sc.solver.max_wall_time
        if self.status != "running" or self.busy <= limit:
            return False
        self._fail(Failure.WALL_TIME_LIMIT, self.t, limit)
        return True

    def _fail(self, kind: Failure, t: float, value: float) -> None:
        text = diagnosis_text(self.model, kind, t, value)
        self.diagnosis = Diagnosis(kind, t, value, text)
        self.status = "failed"

    def _loop_arrays(self) -> tuple:
        """(``kernel.LoopModel``, ``kernel.LoopState``) of this solve (the state anew after
        :meth:`_grow`)."""
        if self._args is None:
            state = K.LoopState(*(getattr(self, name) for name in _STATE_ATTRIBUTES))
            self._args = (self.loop_model, state)
            self._solve = None
        return self._args

    def _call(self, attempts: int, t_target: float) -> int:
        """One call of ``kernel.solve`` (at most ``attempts`` step attempts); grows a full
        buffer, ends the solve when the loop ends it."""
        model, state = self._loop_arrays()
        if self._solve is None:
            self._solve = K.solve.entry(model, state)
        t0 = self.clock()
        status = self._solve(model, state, attempts, float(t_target))
        self.busy += self.clock() - t0
        self._n_props[0] = self.counters["n_props"][0]
        if status == K.SOLVE_GROW:
            self._grow()
        elif status == K.SOLVE_DONE:
            code = int(self.counters["diag"][0])
            if code == K.DIAG_NONE:
                self.status = "finished"
            else:
                self._fail(_FAILURES[code], self.figures["diag_t"][0], self._diag_value(code))
        return status

    def _diag_value(self, code: int) -> float:
        if code == K.DIAG_NONFINITE:
            return math.nan
        if code == K.DIAG_MIN_DT:
            return self.model.sc.solver.min_dt
        return float(self.figures["diag_v"][0])

    def _grow(self) -> None:
        for name in ("impact_rows", "stage_rows"):
            arr = getattr(self, name)
            c = self.counters[0]
            used = c.n_impacts if name == "impact_rows" else c.n_stages
            if used >= arr.shape[0]:
                bigger = np.zeros((2 * arr.shape[0], arr.shape[1]))
                bigger[:used] = arr[:used]
                setattr(self, name, bigger)
        used = self.counters["n_rec"][0]
        if used >= self.record.shape[0]:
            bigger = np.zeros(2 * self.record.shape[0], K.RECORDED)
            bigger[:used] = self.record[:used]
            self.record = bigger
        self._args = None

    def release(self) -> None:
        """Hand the arrays back for the next solve of the same shape (:func:`run`, once it
        has copied out everything it returns; nothing may use this stepper afterwards)."""
        if self._key is None:
            return
        pool = _WORKSPACES.setdefault(self._key, [])
        if len(pool) < 4 and self.record.shape[0] <= _POOLED_RECORD:
            pool.append(self._loop_arrays()[1])
        self._key = None

    # -- a point integrated elsewhere --------------------------------------------------------

    def observe(self, t: float, y: np.ndarray, lam, out, res, on_belt: bool) -> tuple[bool, bool]:
        """Reduce a point integrated elsewhere (a SciPy baseline's accepted point: state, belt
        wrench, contact slots, resultants) with the loop's own reductions (``kernel.observe``);
        ``(stop, on_belt)`` as the loop has them after it. Then :meth:`diverged` checks it."""
        counters = self.counters
        if (
            counters["n_impacts"][0] >= self.impact_rows.shape[0]
            or counters["n_stages"][0] >= self.stage_rows.shape[0]
            or counters["n_rec"][0] >= self.record.shape[0]
        ):
            self._grow()  # a point adds at most one row to each
        i = int(self.counters["cur"][0])
        self.times[i] = t
        self.states[i] = y
        self.belt_wrench[i] = lam
        self.contact_rows[i] = out
        self.resultant_rows[i] = res
        stop, on_belt = K.observe(
            self.model.P,
            self.model.normals,
            self.settings,
            self.counters,
            self.figures,
            self.times,
            self.states,
            self.belt_wrench,
            self.contact_rows,
            self.resultant_rows,
            self.impact_rows,
            self.stage_rows,
            self.record,
            i,
            on_belt,
        )
        return bool(stop), bool(on_belt)

    def diverged(self) -> Diagnosis | None:
        """The loop's divergence checks (NaN, deep penetration, runaway speed) on the last
        observed point; fails the solve on one."""
        i = int(self.counters["cur"][0])
        code = K.diverged(
            self.model.P,
            self.settings,
            self.figures,
            self.times[i],
            self.states[i],
            self.resultant_rows[i],
        )
        if code != K.DIAG_NONE:
            self.counters["diag"][0] = code
            self._fail(_FAILURES[code], self.figures["diag_t"][0], self._diag_value(code))
        return self.diagnosis

    # -- the result --------------------------------------------------------------------------

    def result(
        self, *, steps: int | None = None, diagnosis: str | None = None, wall: float | None = None
    ) -> SimulationResult:
        """The :class:`SimulationResult` of the solve so far from the loop's reductions
        (``result.make_result``). ``steps``, ``diagnosis``, ``wall``: a caller integrating
        elsewhere (:meth:`observe`) gives its own."""
        # Python numbers, read once each from the records' flat words
        words = self.counters.view(np.int64).tolist()
        counters = {name: words[k] for name, k in _COUNTER_WORD.items()}
        words = self.figures.view(np.float64).tolist()
        figures = {name: words[k] for name, k in _FIGURE_WORD.items()}
        stages = [
            (STAGE_NAMES[int(c)], t) for t, c in self.stage_rows[: counters["n_stages"]].tolist()
        ]
        audit = EnergyAudit(
            max_residual=figures["max_res"],
            min_residual=figures["min_res"],
            flow=figures["flow"],
            e0=figures["e0"],
            t_max=figures["t_max"],
            t_min=figures["t_min"],
            max_rise=figures["max_rise"],
            t_rise=(figures["t_rise0"], figures["t_rise1"]),
            run_min=figures["run_min"],
            t_run_min=figures["t_run_min"],
        )
        md = self.model
        if diagnosis is None and self.diagnosis is not None:
            diagnosis = self.diagnosis.text
        return make_result(
            md,
            float(self.times[counters["cur"]]),
            diagnosis,
            counters["n_steps"] if steps is None else steps,
            counters["n_rejected"],
            self.clock() - self.wall0 if wall is None else wall,
            counters["n_forced"],
            counters["n_events"],
            sorted_=bool(counters["sorted"]),
            touched=bool(counters["touched"]),
            exit_speed=figures["exit_speed"],
            impact_speed=figures["impact_speed"],
            impacts=self.impacts,
            peak_n=figures["peak_n"],
            peak_tip=figures["peak_tip"],
            max_depth=figures["max_depth"],
            y_max=figures["y_max"],
            stages=stages,
            audit=audit,
            series=self.series(md.sc.record, stages),
        )

    def series(self, want, stages=None) -> dict[str, np.ndarray]:
        """The recorded series (each its own array: a field of the loop's RECORDED points, which
        record the time once per group); ``stages``: the run's stage list, if known (the
        recorded stage names are the names in it)."""
        if not want:
            return {}
        # a copy of each series (the record is reused by the next solve once this one is
        # released)
        points = self.record[: self.counters["n_rec"][0]]
        out = {
            name: np.array(points[field] if k < 0 else points[field][:, k])
            for name, field, k in _series_layout(tuple(want))
        }
        if "stage" in out:
            codes = out["stage"].astype(np.intp)
            # the names' string width: the longest present (every stage the run entered was
            # recorded at the point it was entered)
            if not len(codes):
                width = 1
            elif stages:
                width = max(len(name) for name, _ in stages)
            else:
                width = int(_STAGE_LENGTHS[codes].max())
            out["stage"] = _STAGE_BY_WIDTH[width].take(codes)
        return out


class SolveStepper(Protocol):
    """What steps one sorting event, whichever scheme integrates it: :class:`Stepper` (our
    schemes in the compiled loop), ``baselines.ScipyStepper`` (a SciPy ``OdeSolver`` on
    ``kernel.rhs``, its accepted points reduced by the loop's own observer) and
    ``peers.CyrkStepper`` (a CyRK C++ solver on the same ``kernel.rhs``, reduced alike). All
    end their steps on :func:`segments` and report through :meth:`Stepper.result`; ``simulate``
    and the soft-real-time line step any of them (``simulate.solve_stepper``)."""

    model: SortingModel
    t_end: float
    status: str  # running, finished or failed
    diagnosis: Diagnosis | None  # why a failed solve failed

    @property
    def t(self) -> float: ...  # the last accepted point

    @property
    def y(self) -> np.ndarray: ...

    @property
    def running(self) -> bool: ...

    @property
    def resultants(self) -> np.ndarray: ...  # the RESULT record at t

    @property
    def contacts(self) -> np.ndarray: ...  # the contact slots (CONTACT) at t

    @property
    def stage(self) -> Stage: ...

    @property
    def sorted(self) -> bool: ...

    @property
    def impacts(self) -> list[tuple[float, float, float]]: ...

    def step(self) -> str | None: ...  # to the next accepted point: None or the diagnosis

    def advance(self, t_target: float = math.inf) -> bool: ...  # False once ended

    def start(self) -> None: ...  # the initial point evaluated and reduced

    def result(
        self, *, steps: int | None = None, diagnosis: str | None = None, wall: float | None = None
    ) -> SimulationResult: ...

    def release(self) -> None: ...  # the workspaces handed back (after result)


def run(stepper: SolveStepper) -> SimulationResult:
    """:func:`simulate.simulate`: a stepper's solve to its end, reduced to its result."""
    stepper.advance()
    result = stepper.result()
    stepper.release()
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
