"""One sorting event: build the model a scenario needs and integrate it in time.

Time stepping ("trapezoidal", the default and for now the only method):

- Load: the trapezoidal rule on (x, y, phi) and their rates, implicit in the contact forces
  (fixed-point iteration to ``solver.tolerance``); the contact is soft (4-45 Hz), so the iteration
  contracts at any step the fence needs.
- Fence: modal coordinates of the FEM beam (13) propagated exactly over the step for a modal force
  varying linearly between the step's ends (a 4x4 matrix exponential per mode, Van Loan), so the
  stiff top modes cost nothing and cannot go unstable; modal truncation just drops columns.
- Belt friction (34)-(36): solved implicitly at the step end (friction.implicit_belt_wrench):
  stick holds the relative velocity at exactly zero, as the Karnopp window intends, which a fixed
  explicit step cannot do with a 1e-6 m/s window.
- Events: the drive's breakpoints (0, t1, 2 t1) are hit exactly; contact onset is located by
  regula falsi on the gap D so the impact speed w_n (and N_stiff) does not depend on the step; the
  crossing of y0 = s (sorted) is interpolated. A step whose iteration does not converge is halved.
- Divergence: NaN, a load speed far beyond any source, or a penetration deeper than
  ``contact.deep_penetration`` x min(A, B) stop the solve with ``success = False`` and a diagnosis.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from . import contacts as ct
from .contact import StiffImpact, stiff_impact
from .drive import accel_jump_at, breakpoints, drive_state, peak_rate
from .fence import FenceParams, build_fence
from .friction import implicit_belt_wrench, karnopp_belt_wrench
from .params import ContactParams, ConveyorParams, DriveParams, ParcelParams, SolverParams
from .parcel import ParcelBody, initial_pose, parcel_body
from .surfaces import FlexibleFence, RigidFence

RECORDABLE = ("trajectory", "fence", "forces", "stages")


@dataclass(frozen=True)
class Scenario:
    """Everything one sorting event needs (the scene loader builds it from YAML)."""

    conveyor: ConveyorParams = ConveyorParams()
    parcel: ParcelParams = ParcelParams()
    drive: DriveParams = DriveParams()
    contact: ContactParams = ContactParams()
    solver: SolverParams = SolverParams()
    fence: FenceParams | None = None  # None: stiff fence on a stiff drive
    fence_length: float = 1.2  # R_z [m] of a stiff fence (a flexible one uses fence.length)
    fence_modes: int | None = None  # modal truncation; None keeps every mode
    record: tuple[str, ...] = ()
    # initial (vx, vy, phidot) of C_s over ground; None = riding the belt at belt speed
    initial_velocity: tuple[float, float, float] | None = None
    # constant applied wrench (F_x, F_y, M_z) on the load, for checks and disturbances
    external_wrench: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def length(self) -> float:
        return self.fence.length if self.fence is not None else self.fence_length


@dataclass
class SimulationResult:
    """Outcome of one event; ``series`` holds only the time series the scenario asked for."""

    success: bool
    sorted: bool
    reason: str
    diagnosis: str | None
    peak_contact_force: float  # max of N summed over fence contacts [N]
    peak_contact_force_stiff: float  # max N_stiff over the impacts [N]
    peak_normal_accel: float  # a_N = N / m_p at its peak [m/s^2]
    impact_normal_speed: float  # w_n at the first contact onset [m/s]
    exit_speed_y: float  # ydot when C_s crosses y0 = s [m/s] (nan if not sorted)
    y_max: float  # y_k: largest C_s ordinate reached [m]
    peak_tip_deflection: float  # [m]
    stages: list[tuple[str, float]]
    sim_time: float
    wall_time: float
    steps: int
    rejected_steps: int
    forced_steps: int = 0  # steps taken unconverged across a model discontinuity
    impacts: list[tuple[float, StiffImpact]] = field(default_factory=list)
    series: dict[str, np.ndarray] = field(default_factory=dict)
    model_parts: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """The JSON outcome of ``fence-sorter simulate --json``."""

        def num(v):
            return None if v is None or not math.isfinite(v) else float(v)

        return {
            "success": self.success,
            "sorted": self.sorted,
            "reason": self.reason,
            "diagnosis": self.diagnosis,
            "peak_contact_force_N": num(self.peak_contact_force),
            "peak_contact_force_stiff_N": num(self.peak_contact_force_stiff),
            "peak_normal_accel_mps2": num(self.peak_normal_accel),
            "impact_normal_speed_mps": num(self.impact_normal_speed),
            "exit_speed_y_mps": num(self.exit_speed_y),
            "y_max_m": num(self.y_max),
            "peak_tip_deflection_m": num(self.peak_tip_deflection),
            "stages": [{"stage": s, "start_s": round(t, 9)} for s, t in self.stages],
            "sim_time_s": self.sim_time,
            "wall_time_s": self.wall_time,
            "steps": self.steps,
            "rejected_steps": self.rejected_steps,
            "forced_steps": self.forced_steps,
            "model_parts": list(self.model_parts),
        }


class _Propagators:
    """Exact one-step maps of the damped modes for linearly varying modal force (Van Loan)."""

    def __init__(self, omega: np.ndarray, zeta: np.ndarray):
        m = len(omega)
        self._base = np.zeros((m, 4, 4))
        self._base[:, 0, 1] = 1.0
        self._base[:, 1, 0] = -(omega**2)
        self._base[:, 1, 1] = -2.0 * zeta * omega
        self._base[:, 1, 2] = 1.0
        self._base[:, 2, 3] = 1.0
        self._cache: dict[float, tuple[np.ndarray, ...]] = {}

    def get(self, h: float):
        hit = self._cache.get(h)
        if hit is not None:
            return hit
        e = scipy.linalg.expm(self._base * h)
        # z1 = E11 z0 + E12 [f0, (f1 - f0)/h]  =>  z1 = A z0 + g0 f0 + g1 f1
        a = e[:, :2, :2].copy()
        g0 = e[:, :2, 2] - e[:, :2, 3] / h
        g1 = e[:, :2, 3] / h
        out = (a, g0.copy(), g1.copy())
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[h] = out
        return out


class SortingModel:
    """The parts one scenario needs, built once: no FEM for a stiff fence, no border contact
    for a load that cannot reach the border, no time series nobody asked for."""

    def __init__(self, sc: Scenario):
        self.sc = sc
        self.body: ParcelBody = parcel_body(sc.parcel, sc.conveyor)
        if sc.fence is not None:
            self.fence = FlexibleFence(build_fence(sc.fence), sc.fence_modes)
            self.props = _Propagators(self.fence.omega, self.fence.zeta)
        else:
            self.fence = RigidFence(sc.fence_length)
            self.props = None
        x0, y0, phi0 = initial_pose(self.body, sc.drive.r_s, sc.parcel.lateral_gap, sc.parcel.yaw)
        self.initial = (x0, y0, phi0)
        reach = max(math.hypot(bx, by) for bx, by in self.body.corners)
        steep = sc.drive.alpha_k > math.atan2(1.0, max(sc.contact.mu_fence, 1e-12))
        self.use_border = y0 - reach < 1e-3 or steep
        self.use_tip = True
        parts = ["load", "belt_friction", "fence_contact", "stiff_reference"]
        parts.append("fem_fence" if sc.fence is not None else "rigid_fence")
        if self.use_border:
            parts.append("border_contact")
        parts.extend(f"record:{r}" for r in sc.record)
        self.parts = tuple(parts)

    @property
    def n_modes(self) -> int:
        return self.fence.n_modes


def simulate(sc: Scenario, model: SortingModel | None = None) -> SimulationResult:
    """Run one sorting event from drive start (t = 0) to sorted or the end time."""
    model = model or SortingModel(sc)
    return _Stepper(model).run()


class _Stepper:
    def __init__(self, model: SortingModel):
        self.m = model
        sc = model.sc
        self.sc = sc
        self.body = model.body
        self.fence = model.fence
        self.nm = model.n_modes
        self.inv_mass = (1.0 / self.body.mass, 1.0 / self.body.mass, 1.0 / self.body.inertia)
        self.belt = sc.conveyor.belt_speed
        self.width = sc.conveyor.width
        t_cycle = 2.0 * sc.drive.t1
        self.t_end = sc.solver.t_end if sc.solver.t_end > 0 else t_cycle + sc.solver.settle_time
        self.breaks = sorted(b for b in breakpoints(sc.drive) if b > 0.0) + [self.t_end]
        tip_speed = peak_rate(sc.drive) * model.sc.length
        self.speed_limit = 20.0 * (self.belt + tip_speed) + 10.0
        self.deep = sc.contact.deep_penetration * min(self.body.length_a, self.body.width_b)
        self.record = set(sc.record)
        self.forced = 0
        self.phi_scale = float(np.max(np.abs(self.fence.phi))) if self.nm else 0.0

    # -- one evaluation of all forces at a state --------------------------------------------
    def _evaluate(self, t, q, v, z, lam, weight=None, prev=None):
        d = drive_state(self.sc.drive, t)
        if self.nm:
            self.fence.set_state(d.alpha, d.rate, z[:, 0], z[:, 1])
            modal = np.empty(self.nm)
        else:
            self.fence.set_state(d.alpha, d.rate, None, None)
            modal = None
        ev = ct.evaluate(
            self.body,
            self.sc.contact,
            self.fence,
            (q[0], q[1], q[2], v[0], v[1], v[2]),
            lam,
            use_border=self.m.use_border,
            use_tip=self.m.use_tip,
            modal_out=modal,
            implicit_weight=weight,
            prev_friction=prev,
        )
        if self.nm:
            ev.modal -= self.fence.rigid_modal * d.accel
        ext = self.sc.external_wrench
        ev.fx += ext[0]
        ev.fy += ext[1]
        ev.mz += ext[2]
        return ev

    def _stick_wrench(self, ev):
        """Karnopp's stick branch of (34)-(36): cancel the applied wrench up to the limits."""
        return karnopp_belt_wrench(
            0.0,
            0.0,
            0.0,
            ev.fx,
            ev.fy,
            ev.mz,
            self.body.f_max,
            self.body.t_max,
            math.inf,
            math.inf,
        )

    # -- one trapezoidal step -------------------------------------------------------------------
    def _step(self, h, t, q, v, z, ev0, lam0, on_belt, force=False):
        sv = self.sc.solver
        t1 = t + h
        im = self.inv_mass
        f0 = (ev0.fx + lam0[0], ev0.fy + lam0[1], ev0.mz + lam0[2])
        v_new = [v[k] + h * f0[k] * im[k] for k in range(3)]
        q_new = [q[k] + 0.5 * h * (v[k] + v_new[k]) for k in range(3)]
        if self.nm:
            a, g0, g1 = self.m.props.get(h)
            f0_modal = ev0.modal
            jump = accel_jump_at(self.sc.drive, t)
            if jump:  # the step starts on the far side of the drive's acceleration jump
                f0_modal = f0_modal - self.fence.rigid_modal * jump
            base = np.einsum("mij,mj->mi", a, z) + g0 * f0_modal[:, None]
            z_new = base + g1 * f0_modal[:, None]
        else:
            z_new = z
        ev = None
        lam = lam0
        stuck = False
        prev = None
        for _ in range(sv.max_iterations):
            ev = self._evaluate(t1, q_new, v_new, z_new, lam0, 0.5 * h, prev)
            prev = {(c.kind, c.index): c.friction_force for c in ev.contacts}
            if not all(map(math.isfinite, (ev.fx, ev.fy, ev.mz))):
                return None
            vnf = [v[k] + 0.5 * h * (f0[k] + (ev.fx, ev.fy, ev.mz)[k]) * im[k] for k in range(3)]
            if on_belt:
                u_star = (vnf[0] - self.belt, vnf[1], vnf[2])
                w = (0.5 * h * im[0], 0.5 * h * im[1], 0.5 * h * im[2])
                lam, _, stuck = implicit_belt_wrench(u_star, w, self.body.f_max, self.body.t_max)
                v_it = [vnf[k] + w[k] * lam[k] for k in range(3)]
                if stuck:
                    v_it[0] = self.belt  # exactly zero relative velocity
            else:
                lam, stuck = (0.0, 0.0, 0.0), False
                v_it = vnf
            q_it = [q[k] + 0.5 * h * (v[k] + v_it[k]) for k in range(3)]
            err = max(abs(q_it[k] - q_new[k]) + h * abs(v_it[k] - v_new[k]) for k in range(3))
            if self.nm:
                z_it = base + g1 * ev.modal[:, None]
                err = max(err, float(np.max(np.abs(z_it - z_new))) * self.phi_scale)
                z_new = z_it
            q_new, v_new = q_it, v_it
            if err <= sv.tolerance:
                break
        else:
            if not force:
                return None
            self.forced += 1
        # end-of-step forces at the converged state
        ev = self._evaluate(t1, q_new, v_new, z_new, lam0, 0.5 * h, prev)
        if stuck:
            lam = self._stick_wrench(ev)
        return t1, q_new, v_new, z_new, ev, lam

    def run(self) -> SimulationResult:
        sc, sv = self.sc, self.sc.solver
        wall0 = time.perf_counter()
        q = list(self.m.initial)
        v = list(sc.initial_velocity) if sc.initial_velocity else [self.belt, 0.0, 0.0]
        z = np.zeros((self.nm, 2))
        t = 0.0
        lam = (0.0, 0.0, 0.0)
        on_belt = True
        ev = self._evaluate(t, q, v, z, lam)
        u0 = math.hypot(v[0] - self.belt, v[1])
        if u0 <= sc.contact.v_min and abs(v[2]) <= sc.contact.phidot_min:
            lam = self._stick_wrench(ev)
        else:
            lam = karnopp_belt_wrench(
                v[0] - self.belt,
                v[1],
                v[2],
                ev.fx,
                ev.fy,
                ev.mz,
                self.body.f_max,
                self.body.t_max,
                sc.contact.v_min,
                sc.contact.phidot_min,
            )
        h_nom = sv.dt
        h = h_nom
        steps = rejected = 0
        touched = False
        stage = ct.classify(ev, self.body, q[2], touched)
        stages = [(stage, 0.0)]
        impacts: list[tuple[float, StiffImpact]] = []
        peak_n = peak_tip = 0.0
        y_max = q[1]
        impact_speed = math.nan
        exit_speed = math.nan
        sorted_ = False
        diagnosis = None
        rec: dict[str, list] = {}
        want = self.record

        def record(t, q, v, ev, stage):
            if "trajectory" in want:
                rec.setdefault("t", []).append(t)
                for key, val in zip(
                    ("x", "y", "phi", "vx", "vy", "phidot"), (*q, *v), strict=True
                ):
                    rec.setdefault(key, []).append(val)
            if "fence" in want:
                rec.setdefault("t_fence", []).append(t)
                rec.setdefault("alpha_w", []).append(self.fence.alpha)
                rec.setdefault("tip_deflection", []).append(self.fence.tip_deflection())
            if "forces" in want:
                rec.setdefault("t_forces", []).append(t)
                rec.setdefault("normal_force", []).append(ev.fence_normal)
                rec.setdefault("deformation", []).append(ev.max_depth)
            if "stages" in want:
                rec.setdefault("t_stage", []).append(t)
                rec.setdefault("stage", []).append(stage)

        record(t, q, v, ev, stage)
        next_break = 0
        while t < self.t_end - 1e-12:
            if time.perf_counter() - wall0 > sv.max_wall_time:
                diagnosis = f"wall-time limit {sv.max_wall_time:g} s reached at t = {t:.4f} s"
                break
            while next_break < len(self.breaks) and self.breaks[next_break] <= t + 1e-12:
                next_break += 1
            h_try = min(h, self.breaks[next_break] - t) if next_break < len(self.breaks) else h
            # a step this small that still does not converge straddles a discontinuity of the
            # model (a contact set or friction sign switching): take it and count it
            tiny = h_try <= 1e-3 * h_nom
            out = self._step(h_try, t, q, v, z, ev, lam, on_belt, force=tiny)
            if out is None:
                rejected += 1
                h = h_try / 2.0
                if h < sv.min_dt:
                    diagnosis = (
                        f"step size fell below solver.min_dt={sv.min_dt:g} s at t = {t:.6f} s: "
                        "the contact iteration does not converge (contact too stiff for the step?)"
                    )
                    break
                continue
            t1, q1, v1, z1, ev1, lam1 = out
            # contact onset: locate the first touch of a new impact by the secant on D
            had_fence = any(c.kind != "border" for c in ev.contacts)
            new = [
                c for c in ev1.contacts if c.kind != "border" and ev.gaps.get((c.kind, c.index))
            ]
            if not had_fence and new:
                # regula falsi on D until the step ends just inside the contact (D <= 1e-10 m),
                # so w_n = D' is read at the onset, not a step later
                c = max(new, key=lambda c: c.depth)
                key = (c.kind, c.index)
                lo, d_lo = 0.0, ev.gaps[key][0]
                hi, d_hi = h_try, c.depth
                for _ in range(12):
                    if d_hi <= 1e-10 or d_lo >= 0.0 or hi - lo <= 1e-12:
                        break
                    h_loc = lo + (hi - lo) * (-d_lo / (d_hi - d_lo))
                    h_loc = min(max(h_loc, lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
                    trial = self._step(h_loc, t, q, v, z, ev, lam, on_belt)
                    gap = trial[4].gaps.get(key) if trial is not None else None
                    if gap is None:
                        break
                    if gap[0] > 0.0:
                        hi, d_hi, out = h_loc, gap[0], trial
                    else:
                        lo, d_lo = h_loc, gap[0]
                t1, q1, v1, z1, ev1, lam1 = out
            # sorted: C_s crosses y0 = s
            if q1[1] >= self.width and q[1] < self.width:
                frac = (self.width - q[1]) / (q1[1] - q[1])
                exit_speed = v[1] + frac * (v1[1] - v[1])
                sorted_ = True
            steps += 1
            t, q, v, z, ev, lam = t1, q1, v1, z1, ev1, lam1
            h = min(h_nom, 2.0 * h)
            # bookkeeping
            fence_cts = [c for c in ev.contacts if c.kind != "border"]
            if fence_cts and not touched:
                touched = True
            if fence_cts and not had_fence:
                rate = max(c.depth_rate for c in fence_cts)
                gap = ev.gaps.get((fence_cts[0].kind, fence_cts[0].index))
                w_n = gap[1] if gap else rate
                if math.isnan(impact_speed):
                    impact_speed = w_n
                impacts.append((t, stiff_impact(self.body.mass, w_n, sc.contact)))
            peak_n = max(peak_n, ev.fence_normal)
            peak_tip = max(peak_tip, abs(self.fence.tip_deflection()))
            y_max = max(y_max, q[1])
            new_stage = ct.STAGE_SORTED if sorted_ else ct.classify(ev, self.body, q[2], touched)
            if new_stage != stage:
                stage = new_stage
                stages.append((stage, t))
            record(t, q, v, ev, stage)
            # divergence checks
            if not all(map(math.isfinite, (*q, *v))) or (self.nm and not np.isfinite(z).all()):
                diagnosis = f"non-finite state at t = {t:.6f} s"
                break
            if ev.max_depth > self.deep:
                diagnosis = (
                    f"deep penetration D = {ev.max_depth:.4g} m > {self.deep:.4g} m "
                    f"at t = {t:.6f} s: the solve diverged or the load passed through the fence"
                )
                break
            if math.hypot(v[0], v[1]) > self.speed_limit:
                diagnosis = (
                    f"load speed {math.hypot(v[0], v[1]):.4g} m/s exceeds {self.speed_limit:.4g} "
                    f"m/s at t = {t:.6f} s: runaway energy, the solve diverged"
                )
                break
            if sorted_ and sv.stop_when_sorted:
                break
            if sorted_ and on_belt:
                on_belt = False  # the load has left the belt into the chute
        wall = time.perf_counter() - wall0
        peak_stiff = max((imp.peak_force for _, imp in impacts), default=0.0)
        if diagnosis is not None:
            reason = "solver failure: " + diagnosis
        elif sorted_:
            reason = "sorted: centre of gravity crossed the chute edge y0 = s"
        elif not touched:
            reason = "not sorted: the fence never touched the load"
        else:
            reason = f"not sorted: y_max = {y_max:.3f} m < s = {self.width:g} m"
        series = {k: np.asarray(vals) for k, vals in rec.items()}
        return SimulationResult(
            success=diagnosis is None,
            sorted=sorted_ and diagnosis is None,
            reason=reason,
            diagnosis=diagnosis,
            peak_contact_force=peak_n,
            peak_contact_force_stiff=peak_stiff,
            peak_normal_accel=peak_n / self.body.mass,
            impact_normal_speed=impact_speed,
            exit_speed_y=exit_speed,
            y_max=y_max,
            peak_tip_deflection=peak_tip,
            stages=stages,
            sim_time=t,
            wall_time=wall,
            steps=steps,
            rejected_steps=rejected,
            forced_steps=self.forced,
            impacts=impacts,
            series=series,
            model_parts=self.m.parts,
        )
