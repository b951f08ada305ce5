"""The one-fence sorting line: many parcels on the belt, one rotary fence, strokes integrated
in step (a line of several fence units is :mod:`fence_sorter.line.multi_unit`).

Parcels ride the belt kinematically (front x_f(t) = scan_position_x + v (t - scan_time), frame
sorter, C_s from :func:`fence_sorter.physics.parcel.initial_pose`) until their stroke starts.
A stroke starts when the commanded parcel's front reaches R_s (``START_AT_RS``) or at a given
time (``START_AT_TIME``); the fence is then busy for one cycle t_c = t1 + t2 = 2 t1. Each stroke
is one physics :class:`~fence_sorter.physics.simulate.Scenario` (the parcel, DriveParams(alpha_k,
t1, R_s) with R_s the front position at the start, the line's conveyor/fence/contact/solver)
stepped by its stepper (``physics.simulate.solve_stepper``) in step with the line clock,
so the event is integrated as sim time passes, never precomputed. The solve runs on after the
parcel is sorted to the solver's end (2 t1 + settle_time): the fence shape comes from it through
the cycle and the ring-down after it, until the next stroke starts (its solve starts with the
fence at rest). A parcel that is not sorted stays in its solve to the solver's end and then
rides on.

Every parcel gets exactly one :class:`Outcome`. Not modelled: parcel-parcel contact and the
fence acting on any parcel other than its stroke's; a parcel inside the fence's swept sector
during another parcel's stroke is reported as :class:`OverlapWarning`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from fence_sorter.codes import StartMode, decline_code
from fence_sorter.inputs import (
    SCAN_LINE_TOLERANCE,
    ParcelSpec,
    StrokeCommand,
    validate_command,
    validate_parcel,
)
from fence_sorter.physics.drive import drive_state
from fence_sorter.physics.fence import (
    FenceParams,
    build_fence,
    natural_frequencies,
    node_positions,
)
from fence_sorter.physics.params import (
    ContactParams,
    ConveyorParams,
    DriveParams,
    SolverParams,
)
from fence_sorter.physics.parcel import parcel_body, world_corners
from fence_sorter.physics.simulate import (
    Scenario,
    SimulationResult,
)

from .sector import in_swept_sector
from .stroke import HELD, LineParcel, Stroke
from .types import (
    NAN,
    CommandResult,
    FenceSnapshot,
    LineEvent,
    LineSnapshot,
    Outcome,
    OutcomeCode,
    OverlapWarning,
    ParcelSnapshot,
    SolverWarning,
    Stage,
    StrokeStarted,
)

#: nodes drawn along a stiff fence (it has no FEM mesh)
STIFF_NODES = 11
#: the largest step of a flexible fence's solve on the line, omega_2 h [rad] (below 0.2 the
#: trapezoid's period error of the first two modes, (omega h)^2 / 12, stays within 1/300)
RING_STEP = 0.2


@dataclass(frozen=True)
class LineConfig:
    """The line: conveyor, fence, contact and solver of a scene plus the line geometry.

    ``r_s_range``: R_s a command may ask for (paper range (3)); its upper end is the point of no
    return of a divert parcel (front passing it with no accepted command: NO_COMMAND).
    ``line_end_x``: a parcel whose rear passes it leaves the line. ``scan_line_x``: where the
    scanner measures (a parcel's scan_position_x must lie within ``scan_line_tolerance`` of
    it); None: any scan_position_x within the position bound.
    """

    conveyor: ConveyorParams = ConveyorParams()
    contact: ContactParams = ContactParams()
    solver: SolverParams = SolverParams()
    fence: FenceParams | None = None  # None: stiff fence
    fence_length: float = 1.2  # R_z of a stiff fence [m]
    fence_modes: int | None = None
    r_s_range: tuple[float, float] = (-0.5, 2.0)
    line_end_x: float = 3.0
    scan_line_x: float | None = None
    scan_line_tolerance: float = SCAN_LINE_TOLERANCE

    @classmethod
    def from_scenario(cls, sc: Scenario, **line: object) -> LineConfig:
        """The line of a scene's Scenario (its parcel and drive are per-parcel/per-command)."""
        return cls(
            conveyor=sc.conveyor,
            contact=sc.contact,
            solver=sc.solver,
            fence=sc.fence,
            fence_length=sc.fence_length,
            fence_modes=sc.fence_modes,
            **line,
        )

    @property
    def length(self) -> float:
        return self.fence.length if self.fence is not None else self.fence_length

    def validate(self) -> None:
        """Raise ValueError naming the setting: bad geometry or an unknown solver. Every
        scheme steps on the line (``simulate.solve_stepper``): ours, the SciPy baselines and
        the compiled peers; whether a paced run keeps real time with one is its pacing
        figures' to say."""
        self.solver.validate()
        lo, hi = self.r_s_range
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"r_s_range must be finite with min < max, got {self.r_s_range}")
        if self.scan_line_x is not None and not (
            math.isfinite(self.scan_line_x) and self.scan_line_tolerance >= 0.0
        ):
            raise ValueError(
                f"scan_line_x must be finite and scan_line_tolerance in [0, inf), got "
                f"{self.scan_line_x!r} and {self.scan_line_tolerance!r}"
            )
        if not math.isfinite(self.line_end_x) or self.line_end_x <= hi:
            raise ValueError(
                f"line_end_x must exceed the point of no return r_s_range[1] = {hi:g} m, "
                f"got {self.line_end_x!r}"
            )


class LineCapture(NamedTuple):
    """What :meth:`SortingLine.capture` took at time ``t``, as plain numbers (cheap to pickle
    and to send to another process; :meth:`SortingLine.render` builds the snapshot from it).

    ``fence``: None at rest, else (alpha_w, rate, accel, w_free or None, stroke parcel id,
    from_solve), w_free being the fence's nodal displacements (root excluded) when a
    flexible fence's solve gives them. ``parcels``: per parcel, the fields of
    :class:`ParcelSnapshot` in order, the stage as its value.
    """

    t: float
    fence: tuple | None
    parcels: list[tuple]


class SortingLine:
    """The line model under the simulator node: plain methods, sim time in seconds.

    Use: :meth:`add_parcel` for each scanned parcel, :meth:`command` for each fence command,
    :meth:`advance` to move sim time on (returns the events, outcomes among them),
    :meth:`snapshot` for the fence and every parcel at the current time.
    """

    def __init__(self, config: LineConfig, t0: float = 0.0):
        config.validate()
        # the line steps solves as its clock moves: a stroke's solve is not cut off by the
        # solver's wall-clock limit (the pacer reports a slow one), so lift it to its maximum
        # (see docs/design/simulator.md)
        solver = replace(config.solver, stop_when_sorted=False, max_wall_time=3600.0)
        self.fem = build_fence(config.fence) if config.fence is not None else None
        if self.fem is not None:
            # the fence's state is published (the sensors' truth): steps resolve its first two
            # modes (the first if only one is kept), a trapezoid's period error
            # (omega h)^2 / 12 within 1/300
            kept = 2 if config.fence_modes is None or config.fence_modes >= 2 else 1
            omega = 2.0 * math.pi * float(natural_frequencies(self.fem, kept)[-1])
            solver = replace(solver, dt_max=min(solver.dt_max, RING_STEP / omega))
        self.config = replace(config, solver=solver)
        self.t = float(t0)
        self.v = config.conveyor.belt_speed
        self.parcels: dict[int, LineParcel] = {}
        self.done_ids: set[int] = set()  # parcels that had their outcome (ids stay taken)
        self.strokes: list[Stroke] = []
        self._build_cost = 0.0  # wall time of the costliest recent stroke build [s] (prefetch)
        self.events: list[LineEvent] = []
        self._rest_s = (
            np.asarray(self.fem.node_s, dtype=float)
            if self.fem is not None
            else np.linspace(0.0, config.fence_length, STIFF_NODES)
        )

    # -- input --------------------------------------------------------------------------------
    def add_parcel(self, spec: ParcelSpec, t: float | None = None) -> None:
        """Put a scanned parcel on the belt; raises InputError (a ValueError) naming the field.

        The parcel's scan_time must lie in the window around the line's time (``t``, the line
        time the message arrived, when it is ahead) of :func:`fence_sorter.inputs.
        validate_parcel`; its position follows its own scan_time and scan_position_x.
        """
        now = self.t if t is None else max(self.t, t)
        validate_parcel(
            spec,
            self.config.conveyor.width,
            self.parcels.keys() | self.done_ids,
            now=now,
            scan_line_x=self.config.scan_line_x,
            scan_line_tolerance=self.config.scan_line_tolerance,
        )
        conv = self._conveyor(spec)
        body = parcel_body(spec.to_parcel_params(), conv)
        p = LineParcel(spec, body, self.v)
        p.t_enter = p.time_front_at(0.0)
        self.parcels[spec.parcel_id] = p

    def command(self, cmd: StrokeCommand, t: float | None = None) -> CommandResult:
        """Accept or reject a stroke command (see :class:`CommandResult` for the codes)."""
        now = self.t if t is None else max(self.t, t)
        p = self.parcels.get(cmd.parcel_id)
        if p is None:
            if cmd.parcel_id in self.done_ids:
                return CommandResult(
                    False, "parcel_done", f"parcel {cmd.parcel_id} already has its outcome"
                )
            return CommandResult(False, "unknown_parcel", f"unknown parcel_id {cmd.parcel_id}")
        if p.outcome is not None or p.stroke is not None or p.passed:
            return CommandResult(
                False, "parcel_done", f"parcel {cmd.parcel_id} already has its stroke or outcome"
            )
        if p.command is not None:
            return CommandResult(
                False,
                "duplicate",
                f"parcel {cmd.parcel_id} already has a stroke planned at t = {p.t_start:.4f} s",
            )
        if not p.spec.divert:
            return CommandResult(
                False, "not_divert", f"parcel {cmd.parcel_id} is not to be diverted"
            )
        if not cmd.feasible:
            reason = cmd.reason or "the controller found no feasible stroke"
            code = decline_code(reason)
            text = (
                reason
                if code is OutcomeCode.NO_STROKE_IN_BUDGET
                else f"no feasible stroke: {reason}"
            )
            self._finish(p, code, now, text)
            return CommandResult(True, "infeasible", reason)
        try:
            validate_command(cmd, self.config.r_s_range)
        except ValueError as exc:
            p.rejected = f"invalid command: {exc}"
            return CommandResult(False, "invalid", str(exc))
        if cmd.start_mode == StartMode.AT_RS:
            t_start = p.time_front_at(cmd.r_s)
            r_s = float(cmd.r_s)
        else:
            t_start = float(cmd.start_time)
            r_s = p.front_at(t_start)
            lo, hi = self.config.r_s_range
            if not lo <= r_s <= hi:
                reason = (
                    f"start_time {t_start:.4f} s puts the parcel front at x0 = {r_s:.3f} m, "
                    f"outside the R_s range [{lo:g}, {hi:g}] m"
                )
                p.rejected = f"invalid command: {reason}"
                return CommandResult(False, "invalid", reason)
        if t_start < now - 1e-9:
            p.late = (
                f"command arrived late: the stroke had to start at t = {t_start:.4f} s, "
                f"the command came at t = {now:.4f} s ({now - t_start:.4f} s late)"
            )
            return CommandResult(False, "late", p.late)
        t_leave = p.rear_end_time(self.config.line_end_x)
        if t_start + cmd.t1 > t_leave + 1e-9:
            reason = (
                f"outside its parcel's window: the working motion would end at "
                f"t = {t_start + cmd.t1:.4f} s, after parcel {cmd.parcel_id} leaves the line "
                f"(t = {t_leave:.4f} s); t1 must be in [0.02, {max(t_leave - t_start, 0.0):.4g}] s"
            )
            p.rejected = f"invalid command: {reason}"
            return CommandResult(False, "outside_window", reason)
        t_end = t_start + 2.0 * cmd.t1
        for other in self._planned():
            if other is p:
                continue
            o_start = other.t_start
            o_end = o_start + 2.0 * other.command.t1
            if t_start < o_end - 1e-9 and o_start < t_end - 1e-9:
                reason = (
                    f"fence busy: stroke [{t_start:.4f}, {t_end:.4f}] s overlaps parcel "
                    f"{other.spec.parcel_id}'s [{o_start:.4f}, {o_end:.4f}] s"
                )
                p.rejected = reason
                return CommandResult(False, "fence_busy", reason)
        p.command = cmd
        p.t_start = t_start
        p.r_s = r_s
        p.rejected = p.late = None
        return CommandResult(True, "accepted", "", t_start)

    # -- time ---------------------------------------------------------------------------------
    def advance(self, t_target: float) -> list[LineEvent]:
        """Move sim time to ``t_target``, handling stroke starts, points of no return and line
        ends in time order; return the events since the last call (outcomes among them)."""
        t_target = max(float(t_target), self.t)
        while True:
            t_ev, kind, p = self._next_event()
            if p is None or t_ev > t_target:
                break
            t_ev = max(t_ev, self.t)
            self._step_strokes(t_ev)
            self.t = t_ev
            if kind == 0:
                self._start_stroke(p)
            elif kind == 1:
                self._no_return(p)
            else:
                self._leave(p)
        self._step_strokes(t_target)
        self.t = t_target
        self._check_overlap()
        events, self.events = self.events, []
        return events

    def prefetch(self, horizon: float, wall_deadline: float, clock=time.perf_counter) -> None:
        """Use spare wall time while ``clock()`` is before ``wall_deadline``: step the running
        solves ahead of the line time by up to ``horizon`` of sim time, build the next planned
        stroke, then step the built strokes' solves ahead, as far as they go. A stroke's solve
        depends on its command and its parcel only (the fence starts each stroke at rest), so
        it can run before the stroke starts. The line time and its events do not move; later
        :meth:`advance` calls find the work done (soft real time: a costly stretch of an event,
        an impact, is spread over the cycles before it is due)."""
        for s in self.strokes:
            if s.alive:
                s.prefetch(self.t + horizon - s.t_start, wall_deadline, clock)
        now = clock()
        self._build_cost *= 0.999  # one slow build (e.g. loading the JIT) is forgotten in ~5 s
        planned = sorted(
            (p for p in self._planned() if p.stroke is None and not p.passed),
            key=lambda q: q.t_start,
        )
        for p in planned:
            if p.prepared is None:
                if now + self._build_cost >= wall_deadline:
                    return
                p.prepared = Stroke(p, p.t_start, self._stroke_scenario(p))
                # the costliest recent build (decays 1 % per build): only built where it fits
                self._build_cost = max(clock() - now, 0.99 * self._build_cost)
            p.prepared.prefetch(math.inf, wall_deadline, clock)
            now = clock()
            if now >= wall_deadline or not p.prepared.finished:
                return

    def awaiting_command(self, skip: frozenset[int] | set[int] = frozenset()) -> tuple[float, int]:
        """(sim time, parcel id) of the first parcel to divert that has no command yet and
        whose front reaches the lowest R_s a command may ask for (``r_s_range[0]``) soonest:
        after that time a command could come too late. (inf, -1) if none (``skip``: ids not
        to wait for). An unpaced caller holds the line there until the command arrives."""
        best = (math.inf, -1)
        lo = self.config.r_s_range[0]
        for p in self.parcels.values():
            pid = p.spec.parcel_id
            if p.spec.divert and p.command is None and p.outcome is None and pid not in skip:
                if p.stroke is None and not p.passed and p.rejected is None:
                    best = min(best, (p.time_front_at(lo), pid))
        return best

    def _next_event(self) -> tuple[float, int, LineParcel | None]:
        """Earliest of: a planned stroke start (0), a point of no return (1), a line end (2)."""
        best = (math.inf, 3, None)
        hi = self.config.r_s_range[1]
        for p in self.parcels.values():
            if p.stroke is not None:
                continue
            if p.command is not None and not p.passed:
                cand = (p.t_start, 0, p)
            elif p.spec.divert and p.outcome is None and not p.passed:
                cand = (p.time_front_at(hi), 1, p)
            else:
                cand = (p.rear_end_time(self.config.line_end_x), 2, p)
            if cand[:2] < best[:2]:
                best = cand
        return best

    def _step_strokes(self, t: float) -> None:
        for s in list(self.strokes):
            s.advance(t - s.t_start)
            self._settle(s, t)

    def _settle(self, s: Stroke, t: float) -> None:
        """Outcome and bookkeeping of a stroke after it advanced to line time ``t``.

        Sorted: outcome at once, the parcel leaves the belt, the solve runs on for the fence
        until the cycle ends. Solver failure: outcome (or a warning if the parcel already had
        one), the parcel's diverged state is dropped, the fence follows the rigid drive to the
        end of its cycle. Solve ended unsorted (2 t1 + settle_time): MISSED, the parcel rides on.
        """
        p = s.parcel
        pid = p.spec.parcel_id
        if s.failed is not None:
            if not s.failure_reported:
                s.failure_reported = True
                if p.outcome is None:
                    self._finish(
                        p, OutcomeCode.SOLVER_FAILURE, t, f"solver failure: {s.failed}", s.result()
                    )
                else:
                    self.events.append(SolverWarning(t, pid, s.failed))
                self.parcels.pop(pid, None)
        elif s.tap.t_sorted is not None and t - s.t_start >= s.tap.t_sorted and p.outcome is None:
            self._finish(p, OutcomeCode.SORTED, t, "sorted: C_s crossed y0 = s", s.sorted_result)
            self.parcels.pop(pid, None)
        elif not s.alive and p.outcome is None:
            res = s.result()
            y, _ = s.tap.at(math.inf)
            self._finish(p, OutcomeCode.MISSED, t, res.reason, res)
            p.x, p.y, p.yaw, p.t_ref = float(y[0]), float(y[1]), float(y[2]), t
            p.rear_offset = min(c[0] for c in world_corners(p.body, 0.0, 0.0, p.yaw))
            p.stroke = None
            p.passed = True
        # past its cycle a stroke whose parcel has its outcome only rings the fence down: it
        # ends with its solve or when the next stroke starts (that solve starts at rest)
        if (
            p.outcome is not None
            and t - s.t_start >= s.t_cycle - 1e-12
            and (not s.alive or self.strokes[-1] is not s)
        ):
            if s.alive:
                s.close()
            self.strokes.remove(s)
            if p.stroke is s:
                p.stroke = None  # no parcel <-> stroke cycle left for the GC

    def _stroke_scenario(self, p: LineParcel) -> Scenario:
        cmd = p.command
        return Scenario(
            conveyor=self._conveyor(p.spec),
            parcel=p.spec.to_parcel_params(),
            # the commanded R_s exactly (START_AT_TIME: the front at start_time)
            drive=DriveParams(alpha_k=cmd.alpha_k, t1=cmd.t1, r_s=p.r_s),
            contact=self._contact(p.spec),
            solver=self.config.solver,
            fence=self.config.fence,
            fence_length=self.config.fence_length,
            fence_modes=self.config.fence_modes,
        )

    def _start_stroke(self, p: LineParcel) -> None:
        cmd = p.command
        stroke, p.prepared = p.prepared, None
        if stroke is None:
            stroke = Stroke(p, self.t, self._stroke_scenario(p))
        # the solve runs in local time: a stroke built ahead (prefetch) starts now all the same
        stroke.t_start = self.t
        p.stroke = stroke
        self.strokes.append(p.stroke)
        self.events.append(StrokeStarted(self.t, p.spec.parcel_id, p.r_s, cmd.t1, cmd.alpha_k))
        self._settle(p.stroke, self.t)

    def _no_return(self, p: LineParcel) -> None:
        hi = self.config.r_s_range[1]
        if p.rejected:
            self._finish(p, OutcomeCode.REJECTED, self.t, f"command rejected: {p.rejected}")
        elif p.late:
            self._finish(p, OutcomeCode.NO_COMMAND, self.t, p.late)
        else:
            self._finish(
                p,
                OutcomeCode.NO_COMMAND,
                self.t,
                f"no command before the point of no return (front at x0 = {hi:g} m)",
            )
        p.passed = True

    def _leave(self, p: LineParcel) -> None:
        if p.outcome is None:
            self._finish(
                p, OutcomeCode.NOT_DIVERTED, self.t, "not to be diverted: passed the line end"
            )
        self.parcels.pop(p.spec.parcel_id, None)

    def _finish(
        self,
        p: LineParcel,
        code: OutcomeCode,
        t: float,
        reason: str,
        res: SimulationResult | None = None,
    ) -> None:
        """Record the parcel's one outcome (with the solve's figures when there was one)."""
        assert p.outcome is None, p.spec.parcel_id
        fig = {}
        if res is not None:
            t_ws = t - p.t_enter if math.isfinite(p.t_enter) else math.nan
            fig = dict(
                peak_normal_force=float(res.peak_contact_force),
                peak_normal_force_stiff=float(res.peak_contact_force_stiff),
                peak_normal_accel=float(res.peak_normal_accel),
                impact_normal_speed=float(res.impact_normal_speed),
                exit_speed_y=float(res.exit_speed_y),
                y_max=float(res.y_max),
                time_in_working_space=max(t_ws, 0.0),
            )
        if p.prepared is not None:  # built ahead, never started
            p.prepared.close()
            p.prepared = None
        p.outcome = Outcome(p.spec.parcel_id, t, code, reason, **fig)
        self.done_ids.add(p.spec.parcel_id)
        self.events.append(p.outcome)
        if res is not None and p.stroke is not None:
            self.events.append(p.stroke.trace(t))

    # -- overlap ------------------------------------------------------------------------------
    def _check_overlap(self) -> None:
        running = [s for s in self.strokes if 0.0 <= self.t - s.t_start <= s.t_cycle]
        if not running:
            return
        for s in running:
            alpha_k = s.sc.drive.alpha_k
            own = s.parcel.spec.parcel_id
            for p in self.parcels.values():
                pid = p.spec.parcel_id
                if pid == own or pid in s.warned:
                    continue
                if in_swept_sector(self._corners(p), self.config.length, alpha_k):
                    s.warned.add(pid)
                    self.events.append(OverlapWarning(self.t, own, pid))

    def _corners(self, p: LineParcel) -> list[tuple[float, float]]:
        """World corners of a parcel now (from its solve while it has one)."""
        s = p.stroke
        if s is not None and s.alive and s.tap.cur is not None:
            y, _ = s.tap.at(self.t - s.t_start)
            return world_corners(p.body, y[0], y[1], y[2])
        return world_corners(p.body, *p.pose(self.t))

    # -- state --------------------------------------------------------------------------------
    def snapshot(self) -> LineSnapshot:
        """Fence and every parcel on the line at the current time (no diverged state ever)."""
        return self.render(self.capture())

    def capture(self) -> LineCapture:
        """The state :meth:`snapshot` needs at the current time, as plain numbers, without the
        costly part (fence node positions, the snapshot objects): :meth:`render` builds the
        snapshot from it later or in another process, whatever the line did meanwhile. For a
        soft-real-time caller: capture in the cycle, render elsewhere."""
        t = self.t
        s = self._fence_stroke()
        fence = None
        at: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # one interpolation per stroke
        if s is not None:
            pid = s.parcel.spec.parcel_id
            t_local = t - s.t_start
            # the drive is prescribed: its angle exactly, not interpolated between steps
            d = drive_state(s.sc.drive, t_local)
            if s.alive and s.tap.cur is not None and s.model.flexible:
                y, _ = at[id(s)] = s.tap.at(t_local)
                w_free = (s.model.phi @ y[6 : 6 + s.model.n_modes]).tolist()
                fence = (d.alpha, d.rate, d.accel, w_free, pid, True)
            else:
                fence = (d.alpha, d.rate, d.accel, None, pid, s.alive)
        parcels = []
        for p in self.parcels.values():
            spec = p.spec
            dims = (spec.length_a, spec.width_b, spec.height)
            st = p.stroke
            if st is not None and st.alive and st.tap.cur is not None:
                y, e = at[id(st)] if id(st) in at else st.tap.at(t - st.t_start)
                x, y_, yaw, vx, vy, wz = y[:6].tolist()
                n, depth, rate, px, py = float(e[3]), float(e[4]), float(e[5]), e[6], e[7]
                # at the line time, not where the solve has run ahead to (prefetch)
                stiff = float(e[HELD + 1]) if n > 0 else 0.0
                parcels.append((
                    spec.parcel_id, int(e[HELD]), x, y_, yaw, vx, vy, wz, n, stiff, depth,
                    rate, (float(px), float(py)), *dims,
                    tuple(world_corners(p.body, x, y_, yaw)), spec.divert,
                ))  # fmt: skip
                continue
            x, y_, yaw = (float(v) for v in p.pose(t))
            stage = Stage.PASSED if p.passed else Stage.ON_BELT
            parcels.append((
                spec.parcel_id, stage.value, x, y_, yaw, self.v, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                (NAN, NAN), *dims, tuple(world_corners(p.body, x, y_, yaw)), spec.divert,
            ))  # fmt: skip
        return LineCapture(t, fence, parcels)

    def render(self, cap: LineCapture) -> LineSnapshot:
        """The snapshot of a :meth:`capture` (the same as :meth:`snapshot` at its time); needs
        only the line's fence geometry, so a copy of the line in another process renders the
        captures of this one."""
        parcels = [ParcelSnapshot(p[0], Stage(p[1]), *p[2:]) for p in cap.parcels]
        return LineSnapshot(cap.t, self._render_fence(cap.fence), parcels)

    def _fence_stroke(self) -> Stroke | None:
        """The stroke the fence's state comes from: the last one started, during its cycle
        and, while its solve runs on (to 2 t1 + settle_time), through the ring-down after it."""
        owner = None
        for s in self.strokes:
            if 0.0 <= self.t - s.t_start and (self.t - s.t_start <= s.t_cycle or s.alive):
                owner = s
        return owner

    def _render_fence(self, fence) -> FenceSnapshot:
        rest = self._rest_s
        zeros = np.zeros(len(rest))
        if fence is None:
            return FenceSnapshot(
                0.0, 0.0, 0.0, rest, rest.copy(), zeros, zeros, zeros, 0.0, None, False
            )
        alpha, rate, accel, w_free, pid, from_solve = fence
        if w_free is not None:
            w_free = np.asarray(w_free)
            x_n, y_n = node_positions(self.fem, w_free, alpha)
            defl = np.concatenate(([0.0], w_free[0::2]))
            rot = np.concatenate(([0.0], w_free[1::2]))
            return FenceSnapshot(
                alpha, rate, accel, rest, x_n, y_n, defl, rot, float(defl[-1]), pid, True
            )
        c, sn = math.cos(alpha), math.sin(alpha)
        return FenceSnapshot(
            alpha, rate, accel, rest, c * rest, sn * rest, zeros, zeros, 0.0, pid, from_solve
        )

    # -- internals ----------------------------------------------------------------------------
    def _planned(self) -> list[LineParcel]:
        return [p for p in self.parcels.values() if p.command is not None] + [
            s.parcel for s in self.strokes if s.parcel.spec.parcel_id not in self.parcels
        ]

    def _conveyor(self, spec: ParcelSpec) -> ConveyorParams:
        c = self.config.conveyor
        return c if math.isnan(spec.mu_belt) else replace(c, mu_belt=float(spec.mu_belt))

    def _contact(self, spec: ParcelSpec) -> ContactParams:
        c = self.config.contact
        return c if math.isnan(spec.mu_fence) else replace(c, mu_fence=float(spec.mu_fence))

    def stroke_scenario(self, parcel_id: int) -> Scenario | None:
        """The physics Scenario of a parcel's running stroke (for checks against simulate())."""
        for s in self.strokes:
            if s.parcel.spec.parcel_id == parcel_id:
                return s.sc
        return None

    @property
    def fence_busy(self) -> bool:
        return self._fence_stroke() is not None

    @property
    def parcels_on_line(self) -> int:
        return len(self.parcels)
