"""A parcel on the one-fence line (:class:`LineParcel`: riding the belt, or in its stroke) and
its stroke (:class:`Stroke`: one sorting event's solve, stepped one accepted point at a time
as the line time passes, with the points a snapshot needs kept in a :class:`_Tap`)."""

from __future__ import annotations

import bisect
import functools
import math

import numpy as np

from fence_sorter.inputs import (
    ParcelSpec,
    StrokeCommand,
)
from fence_sorter.physics import kernel as K
from fence_sorter.physics.dense import hermite
from fence_sorter.physics.parcel import ParcelBody, initial_pose, world_corners
from fence_sorter.physics.simulate import (
    Scenario,
    SimulationResult,
    SortingModel,
    solve_stepper,
)
from fence_sorter.physics.stepper import SolveStepper

from .types import (
    TRACE_COLUMNS,
    EventTrace,
    Outcome,
)

#: index of the first extra of a :class:`_Tap` point that is held between points, not
#: interpolated (the stage, then the current impact's N_stiff)
HELD = 8
#: positions of the fields :class:`_Tap` reads in a RESULT record and a CONTACT slot
_R_ALPHA, _R_RATE, _R_ACCEL, _R_FENCE_N, _R_MAX_D, _R_TIP_W, _R_ACTIVE_MASK = (
    K.RESULT.names.index(f)
    for f in ("alpha", "rate", "accel", "fence_n", "max_d", "tip_w", "active_mask")
)
_BORDER_BITS = (1 << K.SLOT_BORDER) - 1  # the border slots' bits of active_mask
_C_ACTIVE, _C_N, _C_PX, _C_PY, _C_DDOT = (
    K.CONTACT.names.index(f) for f in ("active", "n", "px", "py", "ddot")
)


class _Tap:
    """The accepted points of a stroke's solve a snapshot at the line time may need.

    The solve may run ahead of the line clock (:meth:`SortingLine.prefetch`), so the points
    from the last one at or before the line time onwards are kept (:meth:`trim` drops older
    ones) and :meth:`at` interpolates between the two around the time asked for.
    """

    __slots__ = ("ts", "points", "t_sorted", "width", "trace", "n_sorted")

    def __init__(self, width: float):
        self.ts: list[float] = []
        self.points: list[tuple[np.ndarray, np.ndarray]] = []
        # every accepted point, never trimmed: the event's SortEvent (columns TRACE_COLUMNS)
        self.trace: list[tuple] = []
        self.n_sorted: int | None = None  # trace points up to the crossing of y0 = s
        self.t_sorted: float | None = None  # C_s crossing y0 = s (interpolated) [s]
        self.width = width

    @property
    def cur(self):
        """The last accepted point (t, y, extra), or None before the first."""
        if not self.ts:
            return None
        return (self.ts[-1], *self.points[-1])

    def add(self, stepper: SolveStepper) -> bool:
        """Keep the stepper's last accepted point; True if C_s crossed y0 = s at it."""
        t, y = stepper.t, stepper.y.copy()
        # the records as Python floats, read once (a numpy record's field access costs more
        # than the whole row's tolist)
        res = stepper.resultants.tolist()[0]
        best = None  # the active border slot with the largest n (the first of equals)
        # bit k of active_mask is set with slot k's active flag (kernel.forces): the slots
        # are read only when a border slot carries a force
        if int(res[_R_ACTIVE_MASK]) & _BORDER_BITS:
            for slot in stepper.contacts[: K.SLOT_BORDER].tolist():
                if slot[_C_ACTIVE] and (
                    best is None or (best[_C_N] == best[_C_N] and not slot[_C_N] <= best[_C_N])
                ):  # np.argmax's choice: the first largest, a NaN before any number
                    best = slot
        if best is not None:
            px, py, ddot = best[_C_PX], best[_C_PY], best[_C_DDOT]
        else:
            px = py = math.nan
            ddot = 0.0
        impacts = stepper.impacts
        # held, not interpolated (:meth:`at`): the stage and the current impact's N_stiff at
        # this point, as the solve's reductions had them there
        stage = float(stepper.stage.value)
        extra = np.array(
            [
                res[_R_ALPHA], res[_R_RATE], res[_R_ACCEL], res[_R_FENCE_N], res[_R_MAX_D],
                ddot, px, py, stage, impacts[-1][2] if impacts else 0.0,
            ]
        )  # fmt: skip
        prev = (self.ts[-1], self.points[-1][0]) if self.ts else None
        self.ts.append(t)
        self.points.append((y, extra))
        self.trace.append((
            t, stage, res[_R_ACTIVE_MASK], res[_R_FENCE_N], res[_R_MAX_D], ddot,
            res[_R_TIP_W], res[_R_ALPHA], *y[:6].tolist(),
        ))  # fmt: skip
        if stepper.sorted and self.t_sorted is None:
            t0, y0 = (prev[0], prev[1][1]) if prev is not None else (t, 0.0)
            y1 = y[1]
            frac = (self.width - y0) / (y1 - y0) if y1 > y0 else 1.0
            self.t_sorted = t0 + min(max(frac, 0.0), 1.0) * (t - t0)
            self.n_sorted = len(self.trace)
            return True
        return False

    def trim(self, t: float) -> None:
        """Forget the points before the last one at or before local time ``t``."""
        i = bisect.bisect_right(self.ts, t) - 1
        if i > 0:
            del self.ts[:i]
            del self.points[:i]

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """State vector and extras at local time ``t`` (clamped): every position of the state
        (C_s, yaw, the modal coordinates) by cubic Hermite interpolation with its rate (a
        fence ringing at tens of Hz between adaptive steps of up to dt_max is followed to
        O(h^4)), the rates and the extras linearly."""
        ts, pts = self.ts, self.points
        i = bisect.bisect_right(ts, t)
        if i >= len(ts):
            return pts[-1]
        if i == 0:
            return pts[0]
        t0, t1 = ts[i - 1], ts[i]
        (y0, e0), (y1, e1) = pts[i - 1], pts[i]
        if t1 <= t0:
            return y1, e1
        w = (t - t0) / (t1 - t0)
        e = e0 + w * (e1 - e0)
        e[HELD:] = e0[HELD:]  # stage and N_stiff: the point at or before t
        y = y0 + w * (y1 - y0)
        pos, rate = _position_rate_index(len(y0))
        y[pos] = hermite(t, t0, t1, y0[pos], y1[pos], y0[rate], y1[rate])
        return y, e


@functools.lru_cache(maxsize=8)
def _position_rate_index(n_state: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the positions of a state [x, y, phi, vx, vy, phidot, eta, etadot] and of
    their rates."""
    n = (n_state - 6) // 2
    pos = np.r_[0:3, 6 : 6 + n]
    return pos, pos + np.r_[[3] * 3, [n] * n].astype(int)


class Stroke:
    """One running sorting event: its Scenario, model and stepper (``solve_stepper``: our
    schemes' ``Stepper`` or a SciPy baseline's, one interface), stepped one
    accepted point at a time as the line time passes."""

    def __init__(self, parcel: LineParcel, t_start: float, sc: Scenario):
        self.parcel = parcel
        self.t_start = t_start
        self.sc = sc
        self.model = SortingModel(sc)
        self.stepper = solve_stepper(self.model)
        self.tap = _Tap(sc.conveyor.width)
        # the figures of a SORTED outcome: the solve's reductions at the point where C_s
        # crossed y0 = s, as simulate() reports them, however far the solve runs on since
        self.sorted_result: SimulationResult | None = None
        self.finished = False  # the solve has ended (maybe ahead of the line time)
        self.step_cost = 0.0  # wall time of the costliest recent step (prefetch) [s]
        self.alive = True  # the solve covers the line time (False once past its end)
        self.failed: str | None = None
        self.stepper.start()
        self._take()  # the initial point (t = 0)
        self._next()  # and the first step
        if self.finished:
            self.advance(0.0)
        self.failure_reported = False
        self.steps = 1
        self.warned: set[int] = set()

    @property
    def t_cycle(self) -> float:
        return 2.0 * self.sc.drive.t1

    def _take(self) -> None:
        if self.tap.add(self.stepper):
            self.sorted_result = self.result()

    def _next(self) -> None:
        """One step of the solve; its point is kept unless the solve failed there (a diverged
        point is never data: no snapshot interpolates towards it)."""
        if self.stepper.step() is None:
            self._take()
        self.finished = not self.stepper.running

    def advance(self, t_local: float) -> None:
        """Step the solve to cover local time ``t_local`` (it may already be ahead); the stroke
        stops being ``alive`` once ``t_local`` reaches the end of a finished solve."""
        if not self.alive:
            return
        stepper = self.stepper
        while not self.finished and stepper.t < t_local - 1e-12:
            self._next()
        if self.finished and t_local >= stepper.t - 1e-12:
            self.alive = False
            self.failed = None if stepper.diagnosis is None else stepper.diagnosis.text
        self.tap.trim(t_local)

    def prefetch(self, t_local: float, wall_deadline: float, clock) -> None:
        """Step the solve ahead towards local time ``t_local`` while the costliest recent step
        still fits before ``wall_deadline`` on ``clock()``."""
        now = clock()
        # go on only while the costliest recent step still fits before the deadline (the
        # estimate decays 1 % per step and per prefetch, so one slow step does not stop the
        # stepping ahead for good)
        self.step_cost *= 0.99
        while (
            not self.finished
            and self.stepper.t < t_local - 1e-12
            and now + self.step_cost < wall_deadline
        ):
            self._next()
            then, now = now, clock()
            self.step_cost = max(now - then, 0.99 * self.step_cost)

    def trace(self, t: float) -> EventTrace:
        """The event at every accepted step up to its parcel's outcome at line time ``t`` (a
        sorted parcel: the steps its outcome's figures come from)."""
        tap = self.tap
        n = tap.n_sorted if tap.n_sorted is not None else len(tap.trace)
        steps = np.array(tap.trace[:n], dtype=float).reshape(-1, len(TRACE_COLUMNS))
        t_end = steps[-1, 0] if len(steps) else 0.0
        impacts = [imp for imp in self.stepper.impacts if imp[0] <= t_end]
        contact = self.sc.contact
        return EventTrace(
            self.parcel.spec.parcel_id, t, self.t_start, self.model.mass, contact.b_p,
            contact.k_p, steps, np.array(impacts, dtype=float).reshape(-1, 3),
        )  # fmt: skip

    def close(self) -> None:
        self.alive = False
        self.finished = True

    def result(self) -> SimulationResult:
        """The solve's reductions so far (the figures :func:`simulate` reports)."""
        return self.stepper.result(wall=0.0)


class LineParcel:
    """A parcel on the line: kinematic ride (pose at t_ref, velocity (v, 0, 0)) or a stroke."""

    def __init__(self, spec: ParcelSpec, body: ParcelBody, v: float):
        self.spec = spec
        self.body = body
        self.v = v
        self.x, self.y, self.yaw = initial_pose(
            body, spec.scan_position_x, spec.lateral_gap, spec.yaw
        )
        self.t_ref = spec.scan_time
        self.stroke: Stroke | None = None
        self.command: StrokeCommand | None = None
        self.t_start = math.nan
        self.rejected: str | None = None  # why the last command was refused (fence busy, ...)
        self.late: str | None = None
        self.outcome: Outcome | None = None
        self.passed = False  # stroke done, not sorted: riding on
        self.t_enter = math.nan  # front crossing x0 = 0 (entering the working space)
        # rear corner's x relative to C_s while riding (the yaw does not change on the belt)
        self.rear_offset = min(c[0] for c in world_corners(body, 0.0, 0.0, spec.yaw))
        self.r_s = math.nan  # R_s of the planned stroke [m]
        self.prepared: Stroke | None = None  # the planned stroke, built ahead (prefetch)

    def front_at(self, t: float) -> float:
        """Kinematic front position (scan formula) at time t."""
        return self.spec.scan_position_x + self.v * (t - self.spec.scan_time)

    def time_front_at(self, x: float) -> float:
        return self.spec.scan_time + (x - self.spec.scan_position_x) / self.v

    def rear_end_time(self, x_end: float) -> float:
        """When the rear (lowest corner x) of the riding parcel passes ``x_end``."""
        return self.t_ref + (x_end - self.x - self.rear_offset) / self.v

    def pose(self, t: float) -> tuple[float, float, float]:
        return self.x + self.v * (t - self.t_ref), self.y, self.yaw
