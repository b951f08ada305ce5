"""One sorting event: build the model a scenario needs and integrate it in time.

:class:`SortingModel` packs the parts a scenario needs into the compiled kernel's arrays (no FEM
for a stiff fence, no border contact for a load that cannot reach it, only the modes kept by
``fence.modes``, no time series nobody asked for). :func:`simulate` integrates it with
``solver.method``: our schemes (``integrators``: adaptive, trapezoidal, generalized_alpha; the
first two by default in one compiled loop, ``engine``, ``solver.engine = python`` for the Python
one) or a SciPy ``solve_ivp`` baseline on the same right-hand side (``baselines``: scipy:RK45,
...), and reduces the run to a :class:`SimulationResult`: peaks, impact speed, N_stiff, stages,
an energy audit (the load's energy never rises above the work its power sources did on it).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import kernel as K
from .contacts import STAGE_SORTED, classify
from .drive import peak_rate
from .fence import FenceParams, build_fence, modal_basis
from .params import ContactParams, ConveyorParams, DriveParams, ParcelParams, SolverParams
from .parcel import ParcelBody, initial_pose, parcel_body

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
class EnergyAudit:
    """The balance r(t) = E_load(t) - E_load(0) - W_sources(t), both ways, and E_flow.

    E_load is kinetic energy plus sum k_p D^5 / 5; W_sources the work of the fence surface
    velocity on the contact forces, of the belt velocity on the belt friction, and of the
    external wrench (trapezoidal quadrature over the accepted points). Energy never rises
    without a source: r never grows over any interval ([t1, t2], ``max_rise``); in the elastic
    limit it stays ~0 both ways. E_flow = E_load(0) + integral |P_sources| dt scales the
    quadrature's tolerance.
    """

    max_residual: float = 0.0  # max r (the result's energy_excess) [J]
    min_residual: float = 0.0  # min r: energy dissipated [J]
    flow: float = math.nan  # E_flow [J]
    e0: float = math.nan
    t_max: float = 0.0  # when max_residual happened [s]
    t_min: float = 0.0
    max_rise: float = 0.0  # largest rise of r over any interval [t1, t2] [J]
    t_rise: tuple[float, float] = (0.0, 0.0)  # that interval [s]
    run_min: float = 0.0
    t_run_min: float = 0.0

    def update(self, t: float, r: float) -> None:
        if not math.isfinite(r):
            self.max_residual = self.min_residual = r
            return
        if not math.isfinite(self.max_residual):
            return
        if r > self.max_residual:
            self.max_residual, self.t_max = r, t
        if r < self.min_residual:
            self.min_residual, self.t_min = r, t
        if r < self.run_min:
            self.run_min, self.t_run_min = r, t
        if r - self.run_min > self.max_rise:
            self.max_rise, self.t_rise = r - self.run_min, (self.t_run_min, t)


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
    method: str = ""
    events: int = 0  # contact onsets / releases located
    energy_excess: float = 0.0  # max over t of E_load(t) - E_load(0) - W_sources(t) [J]
    energy: EnergyAudit = field(default_factory=EnergyAudit)  # the whole balance
    max_penetration: float = 0.0  # deepest D of any contact [m]
    # (onset time [s], w_n [m/s], peak N_stiff [N]) per impact
    impacts: list[tuple[float, float, float]] = field(default_factory=list)
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
            "method": self.method,
            "events": self.events,
            "energy_excess_J": num(self.energy_excess),
            "max_penetration_m": num(self.max_penetration),
            "model_parts": list(self.model_parts),
        }


class SortingModel:
    """The parts one scenario needs, packed once for the kernel: no FEM for a stiff fence, only
    the modes ``fence_modes`` keeps, no border contact for a load that cannot reach the border,
    no time series nobody asked for."""

    def __init__(self, sc: Scenario):
        self.sc = sc
        self.body: ParcelBody
        self.body, self.corners, self.normals, self.initial, reach = _load_geometry(
            sc.parcel, sc.conveyor, sc.drive.r_s
        )
        self.mass = self.body.mass
        self.inertia = self.body.inertia
        self.belt = sc.conveyor.belt_speed
        self.flexible = sc.fence is not None
        if self.flexible:
            fem, self.omega, self.zeta, self.phi, self.rigid_modal = _fence_modes(
                sc.fence, sc.fence_modes
            )
            self.fem = fem
            self.n_el = int(sc.fence.elements)
            dl = fem.dl
        else:
            self.fem = None
            self.omega = self.zeta = self.rigid_modal = _NO_MODES
            self.phi = _NO_PHI
            self.n_el = 0
            dl = 0.0
        self.n_modes = len(self.omega)
        self.n_state = 6 + 2 * self.n_modes
        y0 = self.initial[1]
        steep = sc.drive.alpha_k > math.atan2(1.0, max(sc.contact.mu_fence, 1e-12))
        self.use_border = y0 - reach < 1e-3 or steep
        self.P = K.pack(
            alpha_k=sc.drive.alpha_k,
            t1=sc.drive.t1,
            mass=self.mass,
            inertia=self.inertia,
            f_max=self.body.f_max,
            t_max=self.body.t_max,
            b_p=sc.contact.b_p,
            k_p=sc.contact.k_p,
            mu2=sc.contact.mu_fence,
            v_min=sc.contact.v_min,
            phidot_min=sc.contact.phidot_min,
            length=sc.length,
            dl=dl,
            n_el=self.n_el,
            use_border=self.use_border,
            use_tip=True,
            flexible=self.flexible,
            belt=self.belt,
            external=sc.external_wrench,
        )
        tip_speed = peak_rate(sc.drive) * sc.length
        self.speed_limit = 20.0 * (self.belt + tip_speed) + 10.0
        self.deep = sc.contact.deep_penetration * min(self.body.length_a, self.body.width_b)
        parts = ["load", "belt_friction", "fence_contact", "stiff_reference"]
        parts.append("fem_fence" if self.flexible else "rigid_fence")
        if self.use_border:
            parts.append("border_contact")
        parts.extend(f"record:{r}" for r in sc.record)
        self.parts = tuple(parts)

    def initial_state(self) -> np.ndarray:
        """[x, y, phi, vx, vy, phidot, eta, etadot] at t = 0 (fence at rest)."""
        y = np.zeros(self.n_state)
        y[:3] = self.initial
        v = self.sc.initial_velocity
        y[3:6] = v if v is not None else (self.belt, 0.0, 0.0)
        return y

    def kinetic_energy(self, y: np.ndarray) -> float:
        return 0.5 * self.mass * (y[3] ** 2 + y[4] ** 2) + 0.5 * self.inertia * y[5] ** 2


_NO_MODES = np.zeros(0)  # a stiff fence's (empty) modal arrays, shared
_NO_PHI = np.zeros((2, 0))


@functools.lru_cache(maxsize=64)
def _load_geometry(parcel: ParcelParams, conveyor: ConveyorParams, r_s: float):
    """The load's body, corner and face-normal arrays, initial pose (C_s, yaw) and reach (the
    largest corner distance from C_s): pure functions of frozen parameters, shared by every model
    of the same load (the optimiser and the line build a model per event for the same parcels;
    on a cold cache these few NumPy and dataclass calls cost ~0.13 ms of a stiff event). The
    arrays are shared, so nothing may write to them (the kernels only read)."""
    body = parcel_body(parcel, conveyor)
    corners = np.array(body.corners, dtype=float)
    normals = np.array(body.face_normals, dtype=float)
    pose = initial_pose(body, r_s, parcel.lateral_gap, parcel.yaw)
    reach = max(math.hypot(bx, by) for bx, by in body.corners)
    return body, corners, normals, pose, reach


@functools.lru_cache(maxsize=16)
def _fence_modes(fence: FenceParams, count: int | None):
    """FEM and modal basis of a fence (shared by every model of the same fence: the line and
    the controller build one model per stroke, and the eigen-solve costs 0.5-3 ms). The arrays
    are shared, so nothing may write to them."""
    fem = build_fence(fence)
    basis = modal_basis(fem, count=count)
    phi = np.ascontiguousarray(basis.phi, dtype=float)
    return (
        fem,
        np.ascontiguousarray(basis.omega, dtype=float),
        np.ascontiguousarray(basis.zeta, dtype=float),
        phi,
        np.ascontiguousarray(phi.T @ fem.rigid_inertia),
    )


def simulate(sc: Scenario, model: SortingModel | None = None) -> SimulationResult:
    """Run one sorting event from drive start (t = 0) to sorted or the end time."""
    model = model or SortingModel(sc)
    if sc.solver.method.startswith("scipy:"):
        from .baselines import run_solve_ivp

        return run_solve_ivp(model)
    from .engine import run_compiled, uses_compiled

    if uses_compiled(sc):
        return run_compiled(model)
    from .integrators import Integrator

    wall0 = time.perf_counter()
    obs = Observer(model)
    integ = Integrator(model)
    t, diagnosis, steps, rejected = integ.run(obs)
    return obs.result(
        t, diagnosis, steps, rejected, time.perf_counter() - wall0, integ.forced, integ.events
    )


class Observer:
    """Reduces the accepted points of a run to a :class:`SimulationResult` (any method).

    Sorting: C_s crossing y0 = s (interpolated); impacts: a fence contact starting after none,
    with N_stiff from the rigid-wall solve at its w_n; stages E1-E4 from the contact set; the
    energy audit: E_load = kinetic + sum k D^5 / 5 must stay below E_load(0) plus the work of the
    power sources (fence surface velocity times contact force, belt velocity times belt friction)
    and the external wrench.
    """

    def __init__(self, model: SortingModel):
        self.md = model
        sc = model.sc
        self.width = sc.conveyor.width
        self.stop_when_sorted = sc.solver.stop_when_sorted
        self.want = set(sc.record)
        self.rec: dict[str, list] = {}
        self.sorted = False
        self.touched = False
        self.had_fence = False
        self.exit_speed = math.nan
        self.impact_speed = math.nan
        self.impacts: list[tuple[float, float, float]] = []
        self.peak_n = 0.0
        self.peak_tip = 0.0
        self.max_depth = 0.0
        self.y_max = -math.inf
        self.stage = None
        self.stages: list[tuple[str, float]] = []
        self.prev_t = 0.0
        self.prev_y = np.zeros(6)
        self.prev_power = 0.0
        self.work = 0.0
        self.last_n = [0.0, 0.0, 0.0]
        self.last_t = [0.0, 0.0, 0.0]
        self.last_mask = [-1, -1]  # contact masks at the two points before this one
        self.first = True
        self.audit = EnergyAudit()
        self.mask = -1

    def __call__(self, st, on_belt: bool) -> tuple[bool, bool]:
        md, y, res = self.md, st.y, st.res
        t = st.t
        vx, vy, om = y[3], y[4], y[5]
        energy = 0.5 * md.mass * (vx * vx + vy * vy) + 0.5 * md.inertia * om * om
        energy += res[K.R_ENERGY_CONTACT]
        ext = md.sc.external_wrench
        power = res[K.R_POWER_FENCE] + ext[0] * vx + ext[1] * vy + ext[2] * om
        if on_belt:
            power += st.lam[0] * md.belt
        audit = self.audit
        if self.first:
            self.first = False
            audit.e0 = energy
            audit.flow = abs(energy)
            self.y_max = y[1]
        else:
            h = t - self.prev_t
            self.work += 0.5 * h * (power + self.prev_power)
            audit.flow += 0.5 * h * (abs(power) + abs(self.prev_power))
            audit.update(t, energy - audit.e0 - self.work)
            if y[1] >= self.width > self.prev_y[1] and not self.sorted:
                frac = (self.width - self.prev_y[1]) / (y[1] - self.prev_y[1])
                self.exit_speed = self.prev_y[4] + frac * (vy - self.prev_y[4])
                self.sorted = True
        mask = int(res[K.R_ACTIVE_MASK])
        fence_on = (mask & 0xFF) != 0
        if fence_on and not self.had_fence:
            self.touched = True
            slots = np.flatnonzero(st.out[: K.SLOT_BORDER, K.C_ACTIVE])
            w_n = float(st.out[slots, K.C_DDOT].max())
            if math.isnan(self.impact_speed):
                self.impact_speed = w_n
            peak = K.n_stiff(md.mass, w_n, md.sc.contact.b_p, md.sc.contact.k_p)
            self.impacts.append((t, w_n, peak))
        self.had_fence = fence_on
        n = res[K.R_FENCE_N]
        if n > self.peak_n:
            self.peak_n = n
        # a local maximum of N at the previous point: the parabola through the last three
        # points recovers the peak between steps (third-order accurate; adaptive steps), if
        # the same contacts carried the force at all three (N is smooth there; across an
        # event, e.g. a corner sliding off the tip, it is not)
        n1, n2 = self.last_n[1], self.last_n[2]
        masks = self.last_mask
        smooth = masks[0] == masks[1] == mask
        masks[0], masks[1] = masks[1], mask
        if smooth and n2 > n1 and n2 >= n and n1 > 0.0:
            t0, t1 = self.last_t[1], self.last_t[2]
            peak = K.parabola_peak(t0, n1, t1, n2, t, n)
            if peak > self.peak_n:
                self.peak_n = peak
        self.last_n[1], self.last_n[2] = n2, n
        self.last_t[1], self.last_t[2] = self.last_t[2], t
        tip = abs(res[K.R_TIP_W])
        if tip > self.peak_tip:
            self.peak_tip = tip
        if res[K.R_MAX_D] > self.max_depth:
            self.max_depth = res[K.R_MAX_D]
        if y[1] > self.y_max:
            self.y_max = y[1]
        if mask != self.mask or (self.sorted and self.stage != STAGE_SORTED):
            self.mask = mask
            stage = (
                STAGE_SORTED if self.sorted else classify(st.out, md.normals, y[2], self.touched)
            )
            if stage != self.stage:
                self.stage = stage
                self.stages.append((stage, t))
        if self.want:
            self._record(st)
        self.prev_t = t
        self.prev_y[:] = y[:6]
        self.prev_power = power
        return self.sorted and self.stop_when_sorted, on_belt and not self.sorted

    def _record(self, st) -> None:
        rec, want, y = self.rec, self.want, st.y
        if "trajectory" in want:
            rec.setdefault("t", []).append(st.t)
            for k, key in enumerate(("x", "y", "phi", "vx", "vy", "phidot")):
                rec.setdefault(key, []).append(y[k])
        if "fence" in want:
            rec.setdefault("t_fence", []).append(st.t)
            rec.setdefault("alpha_w", []).append(st.res[K.R_ALPHA])
            rec.setdefault("tip_deflection", []).append(st.res[K.R_TIP_W])
        if "forces" in want:
            rec.setdefault("t_forces", []).append(st.t)
            rec.setdefault("normal_force", []).append(st.res[K.R_FENCE_N])
            rec.setdefault("deformation", []).append(st.res[K.R_MAX_D])
        if "stages" in want:
            rec.setdefault("t_stage", []).append(st.t)
            rec.setdefault("stage", []).append(self.stage)

    def result(self, t, diagnosis, steps, rejected, wall, forced=0, events=0) -> SimulationResult:
        return make_result(
            self.md, t, diagnosis, steps, rejected, wall, forced, events,
            sorted_=self.sorted, touched=self.touched, exit_speed=self.exit_speed,
            impact_speed=self.impact_speed, impacts=self.impacts, peak_n=self.peak_n,
            peak_tip=self.peak_tip, max_depth=self.max_depth, y_max=self.y_max,
            stages=self.stages, audit=self.audit,
            series={k: np.asarray(v) for k, v in self.rec.items()},
        )  # fmt: skip


def make_result(
    md: SortingModel, t, diagnosis, steps, rejected, wall, forced, events, *, sorted_, touched,
    exit_speed, impact_speed, impacts, peak_n, peak_tip, max_depth, y_max, stages, audit, series,
) -> SimulationResult:  # fmt: skip
    """The :class:`SimulationResult` of a run from its reductions (``Observer.result``; the
    compiled loop's driver calls it with the loop's figures directly)."""
    width = md.sc.conveyor.width
    success = diagnosis is None
    if not success:
        reason = "solver failure: " + diagnosis
    elif sorted_:
        reason = "sorted: centre of gravity crossed the chute edge y0 = s"
    elif not touched:
        reason = "not sorted: the fence never touched the load"
    else:
        reason = f"not sorted: y_max = {y_max:.3f} m < s = {width:g} m"
    return SimulationResult(
        success=success,
        sorted=sorted_ and success,
        reason=reason,
        diagnosis=diagnosis,
        peak_contact_force=peak_n,
        peak_contact_force_stiff=max((p for _, _, p in impacts), default=0.0),
        peak_normal_accel=peak_n / md.mass,
        impact_normal_speed=impact_speed,
        exit_speed_y=exit_speed,
        y_max=y_max,
        peak_tip_deflection=peak_tip,
        stages=stages,
        sim_time=t,
        wall_time=wall,
        steps=steps,
        rejected_steps=rejected,
        forced_steps=forced,
        method=md.sc.solver.method,
        events=events,
        energy_excess=audit.max_residual,
        energy=audit,
        max_penetration=max_depth,
        impacts=impacts,
        series=series,
        model_parts=md.parts,
    )
