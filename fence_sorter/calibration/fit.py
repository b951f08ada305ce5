"""Fit the twin's physics to a measured bag: robust nonlinear least squares over replays.

Steps (docs/design/calibration.md):

1. **Align.** Each stroke's start, alpha_k and t1 come from the drive encoder
   (:func:`~fence_sorter.calibration.bag.fit_stroke`); the camera frame is placed in the sorter
   frame by a rigid 2D fit (Kabsch) of the poses seen before the strokes start, where the twin
   knows the motion without any fit parameter (the parcel rides the belt).
2. **Fit.** The residuals are the measured camera poses (x, y, yaw) and fence root moments
   minus the twin's replay of the same parcel and stroke, each channel divided by its noise
   level (from the samples before the strokes). Parameters are fitted in log space
   (``scipy.optimize.least_squares``, trust region reflective; Gauss-Newton, then the
   ``soft_l1`` loss), the Jacobian by forward differences: one replay per parcel and
   parameter, every parcel's replays run in parallel (:class:`Evaluator`). A fit that ends
   in a wrong basin of the cost restarts from a better point (:func:`_escape`).
3. **Judge.** The covariance of the estimate over the parameters and the camera frame is the
   M-estimator's sandwich with each channel's noise level re-estimated from its residuals
   (:func:`_covariance`), the Jacobian by central differences over +- 1 sd
   (:meth:`_Problem.secant_jac`), the strokes' encoder errors carried in as known nuisance
   parameters (:func:`stroke_covariance`, :meth:`_Problem.stroke_derivatives`); 95 %
   intervals exp(z +- 1.96 sd) and the correlation matrix. A
   parameter whose interval spans more than a factor exp(2 ``max_log_halfwidth``) (or that
   ends on a bound) is flagged as not identifiable by this data, fixed at the scene's value,
   and the others are refitted without it.
"""

from __future__ import annotations

import contextlib
import math
import resource
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares

from fence_sorter.physics.simulate import Scenario

from .bag import MeasuredBag
from .evaluate import Evaluator
from .events import (
    CalibrationInputError,
    EventData,
    FitError,
    align_camera,
    event_data,
    pre_stroke_centre,
)
from .replay import PARAMETERS, ParcelEvent, scene_value
from .sensors import camera_to_sorter, drive_angle, sorter_to_camera

Z95 = 1.959964
#: initial noise levels of the first pass: position [m], yaw [rad], root moment [N m]
NOMINAL_SIGMA = (2e-3, 1e-2, 1.0)
SIGMA_FLOOR = (1e-8, 1e-8, 1e-8)
FD_STEP = 1e-4  # forward-difference step in log(parameter)
OFFSET_STEP = (1e-6, 1e-6, 1e-6)  # [m, m, rad]
TOL = 1e-8  # least_squares' xtol, ftol, gtol
#: the Gauss-Newton stage only brings the robust stage near the optimum: its ftol
START_FTOL = 1e-4
F_SCALE = 3.0  # the robust loss's scale [noise levels]
CACHED_POINTS = 8  # replayed parameter sets and Jacobians a problem keeps


def noise_levels(base: Scenario, eds: list[EventData], offset) -> tuple[float, float, float]:
    """Noise of each channel where the twin knows the truth without any fit parameter: poses
    before the stroke (riding the belt), the root moment before the stroke (fence at rest)."""
    dp, dyaw, mom = [], [], []
    for ed in eds:
        pre = ed.cam_tau < 0.0
        if pre.any():
            px, py, pyaw = pre_stroke_centre(base, ed.ev, ed.cam_tau[pre])
            x, y, yaw = camera_to_sorter(offset, ed.cam_x[pre], ed.cam_y[pre], ed.cam_yaw[pre])
            dp.extend((x - px, y - py))
            dyaw.append(_wrap(yaw - pyaw))
        mom.append(ed.str_m[ed.str_tau < 0.0])
    rms = [_rms(np.concatenate(v)) if v else math.nan for v in (dp, dyaw, mom)]
    return tuple(
        max(r, floor) if math.isfinite(r) else nominal
        for r, floor, nominal in zip(rms, SIGMA_FLOOR, NOMINAL_SIGMA, strict=True)
    )


#: a stroke's parameters as fitted from the drive encoder (:func:`~.bag.fit_stroke`)
STROKE_FIELDS = ("t_start", "alpha_k", "t1")


def stroke_covariance(enc_t: np.ndarray, enc_angle: np.ndarray, ev: ParcelEvent,
                      noise: float) -> np.ndarray:  # fmt: skip
    """Covariance of ``ev``'s (t_start, alpha_k, t1) as fitted from the encoder samples
    (``noise``: their RMS about the fitted strokes [rad]): noise^2 (J^T J)^-1, J the drive
    law's (:func:`~.sensors.drive_angle`) derivatives at the samples (central differences;
    samples outside the stroke have none). Zero without samples in the stroke (the stroke as
    commanded, taken as known)."""
    t = enc_t[(enc_t >= ev.t_start) & (enc_t <= ev.t_start + 2.0 * ev.t1)]
    if t.size < 2 * len(STROKE_FIELDS):
        return np.zeros((3, 3))
    cols = []
    for name in STROKE_FIELDS:
        h = 1e-7 * (1.0 if name == "t_start" else abs(getattr(ev, name)))
        plus = replace(ev, **{name: getattr(ev, name) + h})
        minus = replace(ev, **{name: getattr(ev, name) - h})
        cols.append((drive_angle([plus], t) - drive_angle([minus], t)) / (2.0 * h))
    j = np.column_stack(cols)
    return noise**2 * np.linalg.pinv(j.T @ j)


# -- residuals ---------------------------------------------------------------------------------
def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def channels(eds: list[EventData], preds, offset) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw residuals (predicted - measured) per channel: position (every x, then every y),
    yaw, moment; the camera samples placed in the sorter frame by ``offset``."""
    xs, ys, yaw, mom = [], [], [], []
    for ed, (x, y, a, mz) in zip(eds, preds, strict=True):
        mx, my, myaw = camera_to_sorter(offset, ed.cam_x, ed.cam_y, ed.cam_yaw)
        xs.append(x - mx)
        ys.append(y - my)
        yaw.append(_wrap(a - myaw))
        mom.append(mz - ed.str_m)
    return np.concatenate(xs + ys), np.concatenate(yaw), np.concatenate(mom)


def weighted(eds, preds, offset, sigma) -> np.ndarray:
    p, a, m = channels(eds, preds, offset)
    return np.concatenate([p / sigma[0], a / sigma[1], m / sigma[2]])


# -- the fit -----------------------------------------------------------------------------------
@dataclass
class Estimate:
    name: str
    prior: float
    value: float | None  # None: not identifiable, not returned as a number
    ci95: tuple[float, float] | None
    log_sd: float  # standard deviation of log(value) from the Jacobian
    verdict: str
    why: str = ""
    bootstrap_ci95: tuple[float, float] | None = None

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "scene_key": PARAMETERS[self.name][0],
            "prior": self.prior,
            "value": self.value,
            "ci95": list(self.ci95) if self.ci95 else None,
            "log_sd": self.log_sd if math.isfinite(self.log_sd) else None,
            "verdict": self.verdict,
            "why": self.why,
            "bootstrap_ci95": list(self.bootstrap_ci95) if self.bootstrap_ci95 else None,
        }


@dataclass
class CalibrationResult:
    estimates: list[Estimate]
    correlation: np.ndarray
    names: list[str]
    singular_values: np.ndarray
    sigma: tuple[float, float, float]
    camera_offset: tuple[float, float, float]
    camera_rms: float
    encoder_rms: float
    parcels: list[int]
    samples: int
    cost: float
    nfev: int
    replays: int
    wall_time: float
    cpu_time: float  # of this process and its worker processes [s]
    worker_cpu_time: float  # of the worker processes alone [s]
    # RMS of the camera positions' residuals in units of their pre-stroke noise (1: the twin
    # follows the parcels to the camera's noise)
    pose_scatter: float = math.nan
    residuals: tuple[np.ndarray, np.ndarray, np.ndarray] = ()
    final_values: dict[str, float] = field(default_factory=dict)
    data: list[EventData] = field(default_factory=list)  # the parcels fitted

    def values(self) -> dict[str, float]:
        """The identified values (what a calibrated scene takes)."""
        return {e.name: e.value for e in self.estimates if e.value is not None}

    def to_dict(self) -> dict:
        return {
            "estimates": [e.to_dict() for e in self.estimates],
            "correlation": {"names": self.names, "matrix": self.correlation.round(6).tolist()},
            "singular_values": self.singular_values.tolist(),
            "noise_sigma": {
                "position_m": self.sigma[0],
                "yaw_rad": self.sigma[1],
                "moment_Nm": self.sigma[2],
            },
            "camera_offset": {
                "x_m": self.camera_offset[0],
                "y_m": self.camera_offset[1],
                "yaw_deg": math.degrees(self.camera_offset[2]),
            },
            "camera_alignment_rms_m": self.camera_rms,
            "encoder_rms_rad": self.encoder_rms,
            "parcels": self.parcels,
            "samples": self.samples,
            "cost": self.cost,
            "function_evaluations": self.nfev,
            "replays": self.replays,
            "wall_time_s": self.wall_time,
            "cpu_time_s": self.cpu_time,
            "worker_cpu_time_s": self.worker_cpu_time,
            "pose_scatter": self.pose_scatter,
        }


def check_fit_names(base: Scenario, names: list[str], scene: str) -> list[str]:
    """Canonical fit names; CalibrationInputError names an unknown or absent parameter."""
    from .replay import canonical  # lazy: loads the kernel (Numba), SciPy

    out = []
    for raw in names:
        name = canonical(raw)
        if name is None:
            raise CalibrationInputError(
                f"--fit {raw}: not a fit parameter; allowed: {', '.join(PARAMETERS)}"
            )
        if scene_value(base, name) is None:
            have = [n for n in PARAMETERS if scene_value(base, n) is not None]
            raise CalibrationInputError(
                f"--fit {raw}: scene {scene} has a stiff fence, no {PARAMETERS[name][0]}; "
                f"this scene's fit parameters: {', '.join(have)}"
            )
        if scene_value(base, name) <= 0.0:
            raise CalibrationInputError(
                f"--fit {raw}: the scene's {PARAMETERS[name][0]} is {scene_value(base, name)!r}; "
                "a fitted parameter needs a positive starting value"
            )
        if name not in out:
            out.append(name)
    if not out:
        raise CalibrationInputError("--fit: give at least one parameter")
    return out


class _Problem:
    """Residuals and Jacobian over z = [log of the ``names``, camera x, y, yaw] (other fit
    parameters ``fixed``). The physics columns by forward differences of replays (one parallel
    batch), the camera columns by differences of the transform alone (no replays)."""

    def __init__(self, evaluate: Evaluator, eds, names, fixed, sigma):
        self.evaluate, self.eds, self.names, self.fixed = evaluate, eds, names, dict(fixed)
        self.sigma = sigma
        self.k = len(names)
        # replays of recent parameter sets and Jacobians by point: the optimiser asks for the
        # residuals at a point it already evaluated (the accepted trial, a stage's start, the
        # final prediction), and a stage's Jacobian at the point the last stage ended on
        self._preds: dict[bytes, list] = {}
        self._jacs: dict[bytes, np.ndarray] = {}

    def values(self, z) -> dict[str, float]:
        v = dict(self.fixed)
        v.update({n: float(math.exp(zi)) for n, zi in zip(self.names, z[: self.k], strict=True)})
        return v

    def preds(self, z) -> list:
        key = np.asarray(z[: self.k], dtype=float).tobytes()
        if key not in self._preds:
            if len(self._preds) >= CACHED_POINTS:
                self._preds.pop(next(iter(self._preds)))
            self._preds[key] = self.evaluate([self.values(z)])[0]
        return self._preds[key]

    def fun(self, z) -> np.ndarray:
        return weighted(self.eds, self.preds(z), tuple(z[self.k :]), self.sigma)

    def jac(self, z) -> np.ndarray:
        z = np.asarray(z, dtype=float)
        key = z.tobytes()
        if key not in self._jacs:
            if len(self._jacs) >= CACHED_POINTS:
                self._jacs.pop(next(iter(self._jacs)))
            self._jacs[key] = self._forward_differences(z)
        return self._jacs[key].copy()

    def _forward_differences(self, z: np.ndarray) -> np.ndarray:
        f0 = self.fun(z)
        lo, hi = self.bounds()
        steps, sets = [], []
        for j in range(self.k):
            zj = z.copy()
            h = FD_STEP if zj[j] + FD_STEP <= hi[j] else -FD_STEP
            zj[j] += h
            steps.append(h)
            sets.append(self.values(zj))
        off = tuple(z[self.k :])
        cols = [
            (weighted(self.eds, p, off, self.sigma) - f0) / h
            for p, h in zip(self.evaluate(sets) if sets else [], steps, strict=True)
        ]
        base = self.preds(z)
        for j in range(3):
            o = np.array(off)
            o[j] += OFFSET_STEP[j]
            cols.append((weighted(self.eds, base, tuple(o), self.sigma) - f0) / OFFSET_STEP[j])
        return np.column_stack(cols)

    def secant_jac(self, z, widths) -> np.ndarray:
        """The Jacobian by central differences over +- ``widths`` (log parameter; one-sided
        where a bound is nearer), the camera columns as in :meth:`jac`: the slope over the
        interval's own scale, where the linearisation the interval rests on has to hold (a
        1e-4 difference gives the slope at the estimate alone, and straddles any step left
        in the replays' response)."""
        z = np.asarray(z, dtype=float)
        lo, hi = self.bounds()
        plus, minus = [], []
        for j in range(self.k):
            plus.append(z.copy())
            minus.append(z.copy())
            plus[j][j] = min(z[j] + float(widths[j]), hi[j])
            minus[j][j] = max(z[j] - float(widths[j]), lo[j])
        preds = self.evaluate([self.values(v) for v in plus + minus]) if self.k else []
        off = tuple(z[self.k :])
        jac = self.jac(z)
        for j in range(self.k):
            fp = weighted(self.eds, preds[j], off, self.sigma)
            fm = weighted(self.eds, preds[self.k + j], off, self.sigma)
            jac[:, j] = (fp - fm) / (plus[j][j] - minus[j][j])
        return jac

    def stroke_derivatives(self, z, covariances):
        """Per parcel, (D, C): the residuals' derivatives by its stroke's STROKE_FIELDS
        (central differences over +- 1 sd, one parallel batch) and their covariance
        ``covariances[i]``; for :func:`_covariance`'s ``nuisance``."""
        widths = [np.sqrt(np.maximum(np.diag(c), 0.0)) for c in covariances]
        moved = self.evaluate.strokes(self.values(z), widths)
        base, off = list(self.preds(z)), tuple(z[self.k :])
        for i, (w, c) in enumerate(zip(widths, covariances, strict=True)):
            cols = []
            for j, wj in enumerate(w):
                if wj <= 0.0:
                    cols.append(np.zeros(self.fun(z).size))
                    continue
                f = []
                for p in moved[i][2 * j : 2 * j + 2]:
                    preds = base.copy()
                    preds[i] = p
                    f.append(weighted(self.eds, preds, off, self.sigma))
                cols.append((f[0] - f[1]) / (2.0 * wj))
            yield np.column_stack(cols), c

    def bounds(self):
        lo = [math.log(PARAMETERS[n][1]) for n in self.names] + [-np.inf] * 3
        hi = [math.log(PARAMETERS[n][2]) for n in self.names] + [np.inf] * 3
        return np.array(lo), np.array(hi)


def _solve(problem: _Problem, z0, max_nfev: int):
    """Gauss-Newton (linear loss) from z0, then the robust ``soft_l1`` loss from there: far
    from the optimum every residual is many sigma large, where the robust loss would turn the
    fit into a slow L1 descent; near it the robust loss keeps outliers from dominating."""
    lo, hi = problem.bounds()
    z0 = np.clip(z0, lo + 1e-9, hi - 1e-9)
    nfev = 0
    for loss, ftol in (("linear", START_FTOL), ("soft_l1", TOL)):
        sol = least_squares(
            problem.fun,
            z0,
            jac=problem.jac,
            bounds=(lo, hi),
            method="trf",
            loss=loss,
            f_scale=F_SCALE,
            x_scale=1.0,
            xtol=TOL,
            ftol=ftol,
            gtol=TOL,
            max_nfev=max_nfev,
        )
        nfev += sol.nfev
        if sol.status <= 0 or not np.all(np.isfinite(sol.x)):
            raise FitError(
                f"the fit of {', '.join(problem.names)} did not converge in {nfev} "
                f"evaluations (status {sol.status}: {sol.message})"
            )
        z0 = sol.x
    sol.nfev = nfev
    return sol


#: a fit whose position residuals scatter by more than this factor (in variance) of the
#: noise level seen before the strokes sits in a wrong basin of the cost (the default of
#: ``calibrate``'s ``max_pose_scatter``, its square root)
WRONG_BASIN = 2.0
#: where :func:`_escape` looks for a better basin: moves of one parameter [log]
BASIN_STEPS = (-0.2, -0.1, -0.05, -0.02, 0.02, 0.05, 0.1, 0.2)
#: moves at least this large [log] leave the basin they start from; smaller ones fall back
BASIN_JUMP = 0.05


def _position_misfit(problem: _Problem, x: np.ndarray, n_position: int) -> float:
    """The mean square of the position residuals in units of the pre-stroke noise (1 in the
    truth's basin)."""
    r = problem.fun(x)[:n_position]
    return float(np.mean(r**2)) if r.size else 0.0


def _escape(
    problem: _Problem, sol, n_position: int, max_nfev: int, limit: float = WRONG_BASIN,
    rounds: int = 2,
):  # fmt: skip
    """``sol``, or a better local optimum if it sits in a wrong basin. The cost is not convex
    far from the truth: a parcel that sticks to the fence or slides along it, is sorted or
    not, switches with a friction coefficient, and Gauss-Newton from the scene's values can
    end between two such switches (position residuals several times the pre-stroke noise;
    ``limit`` is the largest mean square accepted, in units of that noise's variance). Then
    each parameter is moved alone by BASIN_STEPS (one parallel batch) and the fit is
    restarted from the lowest point if it is lower; at most ``rounds`` times. Where the
    other parameters have compensated, no single move is lower although the truth's basin
    lies one move away: then the fit restarts from the moves of at least BASIN_JUMP in
    order of their cost until one ends in a basin whose residuals scatter as the noise."""
    nfev = sol.nfev
    for round_ in range(rounds + 1):
        r = problem.fun(sol.x)
        if not r[:n_position].size or np.mean(r[:n_position] ** 2) <= limit:
            break
        lo, hi = problem.bounds()
        points, steps = [], []
        for j in range(problem.k):
            for step in BASIN_STEPS:
                z = sol.x.copy()
                z[j] = min(max(z[j] + step, lo[j] + 1e-9), hi[j] - 1e-9)
                points.append(z)
                steps.append(step)
        off = tuple(sol.x[problem.k :])
        costs = [float(np.sum(weighted(problem.eds, p, off, problem.sigma) ** 2))
                 for p in problem.evaluate([problem.values(z) for z in points])]  # fmt: skip
        if not costs:
            break
        best = int(np.argmin(costs))
        if round_ < rounds and costs[best] < float(r @ r):
            new = _solve(problem, points[best], max_nfev)
            nfev += new.nfev
            if new.cost >= sol.cost:
                break
            sol = new
            continue
        # no lower move: restart from the far moves, the cheapest first
        for i in sorted(range(len(points)), key=costs.__getitem__):
            if abs(steps[i]) < BASIN_JUMP:
                continue
            new = _solve(problem, points[i], max_nfev)
            nfev += new.nfev
            if new.cost < sol.cost and _position_misfit(problem, new.x, n_position) <= limit:
                sol = new
                break
        break
    sol.nfev = nfev
    return sol


#: how far a further start lies from the fit along a weakly determined direction [log]
START_STEP = 0.3


def _restart_along_weak_directions(
    problem: _Problem, sol, n_position: int, max_nfev: int, limit: float, starts: int
):
    """``sol``, or the lower optimum a further start reaches. A wrong basin hides along the
    directions the data determine least (on the stiff fence the contact stiffness and damping
    together): the fit can stay near the prior there with its poses still at their noise. For
    each of the ``starts`` - 1 weakest eigenvectors of J^T J (physics columns) the points
    START_STEP either side are evaluated (one parallel batch) and the fit restarts from the
    lower; it is kept if it ends lower with its poses within ``limit``."""
    if starts <= 1 or problem.k == 0:
        return sol
    jac = problem.jac(sol.x)[:, : problem.k]
    _, vectors = np.linalg.eigh(jac.T @ jac)
    points = []
    for i in range(min(starts - 1, problem.k)):
        for sign in (-1.0, 1.0):
            z = sol.x.copy()
            z[: problem.k] += sign * START_STEP * vectors[:, i]
            points.append(z)
    off = tuple(sol.x[problem.k :])
    costs = [float(np.sum(weighted(problem.eds, p, off, problem.sigma) ** 2))
             for p in problem.evaluate([problem.values(z) for z in points])]  # fmt: skip
    nfev = sol.nfev
    for i in range(0, len(points), 2):
        start = points[i] if costs[i] <= costs[i + 1] else points[i + 1]
        new = _solve(problem, start, max_nfev)
        nfev += new.nfev
        if new.cost < sol.cost and _position_misfit(problem, new.x, n_position) <= limit:
            sol = new
    sol.nfev = nfev
    return sol


def cpu_seconds() -> tuple[float, float]:
    """CPU time [s] of this process and of its ended child processes (a closed Evaluator's
    workers; a Dask cluster's workers are not counted): the load-independent cost of a
    calibration."""
    own, children = (resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                          resource.RUSAGE_CHILDREN))  # fmt: skip
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(r**2))) if r.size else math.nan


def _covariance(
    jac: np.ndarray, r: np.ndarray, sizes: tuple[int, ...], f_scale: float, nuisance=()
):
    """Covariance of the robust (``soft_l1``, scale ``f_scale``) estimate, each channel's
    noise level re-estimated from its residuals.

    ``jac``, ``r``: the Jacobian and residuals (each channel divided by its assumed noise
    level) at the estimate; ``sizes``: the rows of each channel, in order. The M-estimator's
    sandwich A^-1 B A^-1 (Huber 1973) with the loss's influence psi(r) = r / sqrt(1 + (r/c)^2):
    A = J^T diag(a) J, a = the channel's mean psi'(r); B = J^T diag(b) J, b = the channel's
    sum of psi(r)^2 over its degrees of freedom (its rows less the sum of their leverages, the
    hat matrix's diagonal). With Gaussian residuals and every level right this is about
    (J^T J)^-1; a channel whose level was under- or over-estimated (the pre-stroke samples a
    level comes from are few) counts with its actual spread, not with a pooled s^2 that the
    channel with the most samples would set. Returns the covariance (a parameter in a null
    direction of J gets an infinite variance), the singular values of sqrt(a) J and each
    channel's variance factor sum r^2 / dof (its noise level is the assumed one times the
    root of it).

    ``nuisance``: pairs (D, C) of parameters fitted elsewhere and taken as known here (a
    stroke's start, alpha_k and t1 from the encoder), D the residuals' derivatives by them, C
    their covariance. An error e in them moves the estimate by G e with G = -A^-1 J^T diag(a)
    D (the estimating equation J^T psi(r + J dz + D e) = 0 to first order), which adds
    G C G^T to the covariance."""
    u2 = (r / f_scale) ** 2
    psi, dpsi = r / np.sqrt(1.0 + u2), (1.0 + u2) ** -1.5
    a_rows, b_rows = np.ones(r.size), np.ones(r.size)
    bounds = np.cumsum((0, *sizes))
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        if hi > lo:
            a_rows[lo:hi] = dpsi[lo:hi].mean()
    u, sv, vt = np.linalg.svd(jac * np.sqrt(a_rows)[:, None], full_matrices=False)
    keep = sv > sv.max() * 1e-10 if sv.size and sv.max() > 0 else np.zeros(sv.size, bool)
    a_inv = (vt[keep].T / sv[keep] ** 2) @ vt[keep]
    leverage = np.sum(u[:, keep] ** 2, axis=1)
    factors = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        dof = (hi - lo) - float(leverage[lo:hi].sum())
        if hi == lo or dof <= 0.5:
            factors.append(1.0)
            continue
        b_rows[lo:hi] = float(psi[lo:hi] @ psi[lo:hi]) / dof
        factors.append(float(r[lo:hi] @ r[lo:hi]) / dof)
    cov = a_inv @ ((jac.T * b_rows) @ jac) @ a_inv
    jt_a = jac.T * a_rows
    for d, c in nuisance:
        g = a_inv @ (jt_a @ d)
        cov += g @ c @ g.T
    for k in np.flatnonzero(~keep):
        for j in np.flatnonzero(np.abs(vt[k]) > 1e-3):
            cov[j, j] = np.inf
    return cov, sv, tuple(factors)


def calibrate(
    base: Scenario,
    mb: MeasuredBag,
    names: list[str],
    *,
    workers: int | None = None,
    max_log_halfwidth: float = 0.5,
    max_nfev: int = 40,
    min_parcels: int = 3,
    bootstrap: int = 0,
    seed: int = 0,
    progress=None,
    scheduler: str = "processes",
    max_pose_scatter: float = math.sqrt(WRONG_BASIN),
    starts: int = 1,
) -> CalibrationResult:
    """Fit ``names`` of ``base`` to the bag; see the module docstring. ``max_pose_scatter``:
    the largest RMS of the camera positions' residuals after the fit, in units of their noise
    before the strokes, that is taken as the truth's basin; a fit above it restarts and, if no
    restart gets below, fails (a twin with model error on a real machine may need more than
    the default sqrt(2)). ``starts`` > 1: further starts along the least determined
    directions (:func:`_restart_along_weak_directions`)."""
    wall0, cpu0 = time.perf_counter(), cpu_seconds()
    offset0, cam_rms = align_camera(base, mb)
    eds = [ed for ed in event_data(mb, base.solver.settle_time) if (ed.cam_tau > 0.0).sum() >= 3]
    if len(eds) < min_parcels:
        raise CalibrationInputError(
            f"{mb.path}: {len(eds)} parcels with a stroke and camera poses during it; a "
            f"calibration needs at least {min_parcels}"
        )
    sigma = noise_levels(base, eds, offset0)
    stroke_cov = [
        stroke_covariance(mb.m.enc_t, mb.m.enc_angle, ed.ev, mb.encoder_rms) for ed in eds
    ]
    n_cam = sum(ed.cam_tau.size for ed in eds)
    sizes = (2 * n_cam, n_cam, sum(ed.str_tau.size for ed in eds))
    prior = {n: float(scene_value(base, n)) for n in names}
    evaluate = Evaluator(base, eds, workers, scheduler)
    evaluate.on_replays = progress
    active, fixed, flagged = list(names), {}, {}
    z = np.concatenate([np.log([prior[n] for n in names]), offset0])
    nfev = 0
    try:
        while True:
            prob = _Problem(evaluate, eds, active, fixed, sigma)
            limit = max_pose_scatter**2
            sol = _escape(prob, _solve(prob, z, max_nfev), sizes[0], max_nfev, limit)
            sol = _restart_along_weak_directions(prob, sol, sizes[0], max_nfev, limit, starts)
            nfev += sol.nfev
            misfit = _position_misfit(prob, sol.x, sizes[0])
            if misfit > limit:
                raise FitError(
                    f"the fit of {', '.join(active)} ends with the camera poses scattering "
                    f"{math.sqrt(misfit):.2g} times their noise before the strokes "
                    f"(--max-pose-scatter {max_pose_scatter:.3g}): a wrong basin of the "
                    "cost, or a twin that does not fit this machine"
                )
            r = prob.fun(sol.x)
            cov, sv, factors = _covariance(prob.jac(sol.x), r, sizes, F_SCALE)
            # the interval from the slope over +- 1 sd of each parameter
            sd = np.nan_to_num(np.sqrt(np.diag(cov))[: len(active)], nan=0.1, posinf=0.1)
            jac = prob.secant_jac(sol.x, np.clip(sd, FD_STEP, 0.1))
            cov, sv, factors = _covariance(
                jac, r, sizes, F_SCALE, prob.stroke_derivatives(sol.x, stroke_cov)
            )
            sd = np.sqrt(np.diag(cov))
            lo, hi = prob.bounds()
            bad = {}
            for j, n in enumerate(active):
                if not math.isfinite(sd[j]) or Z95 * sd[j] > max_log_halfwidth:
                    bad[n] = (
                        f"the 95 % interval spans a factor {math.exp(2 * Z95 * sd[j]):.3g} "
                        f"(limit {math.exp(2 * max_log_halfwidth):.3g})"
                        if math.isfinite(sd[j])
                        else "the data carry no information on it"
                    )
                elif sol.x[j] - lo[j] < 1e-6 or hi[j] - sol.x[j] < 1e-6:
                    bad[n] = "the estimate ends on its bound"
            if not bad:
                break
            # fix the least determined one at the scene's value and refit the rest
            worst = max(bad, key=lambda n: sd[active.index(n)])
            flagged[worst] = bad[worst]
            fixed[worst] = prior[worst]
            keep = [j for j, n in enumerate(active) if n != worst]
            z = np.concatenate([sol.x[keep], sol.x[len(active) :]])
            active = [n for n in active if n != worst]
        final = prob.values(sol.x)
        offset = tuple(float(v) for v in sol.x[len(active) :])
        preds = prob.preds(sol.x)
        raw = channels(eds, preds, offset)
        levels = tuple(sg * math.sqrt(f) for sg, f in zip(sigma, factors, strict=True))
        boot = _bootstrap(
            evaluate, eds, preds, active, fixed, levels, sol.x, bootstrap, seed, max_nfev,
            stroke_cov,
        )  # fmt: skip
    finally:
        evaluate.close()
    estimates = []
    k = len(active)
    for n in names:
        if n in active:
            j = active.index(n)
            ci = (math.exp(sol.x[j] - Z95 * sd[j]), math.exp(sol.x[j] + Z95 * sd[j]))
            estimates.append(
                Estimate(
                    n,
                    prior[n],
                    math.exp(sol.x[j]),
                    ci,
                    float(sd[j]),
                    "identified",
                    bootstrap_ci95=boot.get(n),
                )
            )
        else:
            estimates.append(
                Estimate(
                    n,
                    prior[n],
                    None,
                    None,
                    math.nan,
                    "not identifiable",
                    why=flagged[n] + "; kept at the scene's value",
                )
            )
    d = np.sqrt(np.diag(cov[:k, :k]))
    corr = cov[:k, :k] / np.outer(d, d)
    return CalibrationResult(
        estimates=estimates,
        correlation=corr,
        names=active,
        singular_values=sv,
        sigma=levels,
        camera_offset=offset,
        camera_rms=cam_rms,
        encoder_rms=mb.encoder_rms,
        parcels=[ed.ev.parcel_id for ed in eds],
        samples=int(sum(r.size for r in raw)),
        cost=float(sol.cost),
        nfev=nfev,
        replays=evaluate.replays,
        wall_time=time.perf_counter() - wall0,
        cpu_time=sum(cpu_seconds()) - sum(cpu0),
        worker_cpu_time=cpu_seconds()[1] - cpu0[1],
        pose_scatter=math.sqrt(misfit),
        residuals=raw,
        final_values=final,
        data=eds,
    )


def _bootstrap(
    evaluate, eds, preds, active, fixed, sigma, z_hat, count, seed, max_nfev, stroke_cov
):
    """Parametric bootstrap: ``count`` refits to the twin's prediction at the estimate plus
    fresh noise of the estimated levels at the measured sample times, each refit replaying
    strokes off by a fresh draw of their encoder errors (``stroke_cov``, per parcel: the
    covariance of start, alpha_k, t1); percentile intervals."""
    if not count or not active:
        return {}
    rng = np.random.default_rng(seed)
    offset = tuple(z_hat[len(active) :])
    draws = []
    for _ in range(count):
        fake = []
        for ed, (x, y, a, mz), c in zip(eds, preds, stroke_cov, strict=True):
            cx, cy, ca = sorter_to_camera(offset, x, y, a)
            d0, dak, dt1 = rng.multivariate_normal(np.zeros(3), c)
            ev = replace(ed.ev, t_start=ed.ev.t_start + d0, alpha_k=ed.ev.alpha_k + dak,
                         t1=ed.ev.t1 + dt1)  # fmt: skip
            fake.append(
                EventData(
                    ev,
                    ed.cam_tau - d0,
                    cx + rng.normal(0, sigma[0], x.size),
                    cy + rng.normal(0, sigma[0], y.size),
                    ca + rng.normal(0, sigma[1], a.size),
                    ed.str_tau - d0,
                    mz + rng.normal(0, sigma[2], mz.size),
                )
            )
        # the refit's replays need the moved strokes: a pool of processes that holds them
        with contextlib.closing(
            Evaluator(evaluate.base, fake, evaluate.workers, evaluate.scheduler)
        ) as moved:
            prob = _Problem(moved, fake, active, fixed, sigma)
            draws.append(_solve(prob, z_hat, max_nfev).x)
            evaluate.replays += moved.replays
    draws = np.array(draws)
    out = {}
    for j, n in enumerate(active):
        lo, hi = np.percentile(draws[:, j], [2.5, 97.5])
        out[n] = (float(math.exp(lo)), float(math.exp(hi)))
    return out
