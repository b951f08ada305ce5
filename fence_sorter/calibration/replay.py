"""Replays of recorded parcels on the twin, and the parameters a calibration may fit.

One :class:`ParcelEvent` is what a bag says about a parcel: the scanner's parcel (size, mass as
weighed, centre of gravity, lateral gap, yaw), the commanded stroke (alpha_k, t1, R_s) and the
stroke's start in bag time (from the drive encoder). :func:`replay` runs that event on the twin
with a scene's physics and chosen parameter values and returns the :class:`Track` the sensors
see: the geometric centre and yaw of the parcel, the fence root's bending moment.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fence_sorter.physics.params import DriveParams, ParcelParams
from fence_sorter.physics.simulate import Scenario, simulate

from .sensors import Track, geometric_centre

#: fit name -> (scene key, lower bound, upper bound): the parameters a calibration may fit.
PARAMETERS: dict[str, tuple[str, float, float]] = {
    "mu_belt": ("conveyor.mu_belt", 0.01, 2.0),
    "mu_fence": ("contact.mu_fence", 0.01, 2.0),
    "k_p": ("contact.k_p", 1e6, 1e13),
    "b_p": ("contact.b_p", 1e2, 1e9),
    "fence.damping_ratio": ("fence.damping_ratio", 1e-4, 0.95),
}
ALIASES = {key: name for name, (key, _, _) in PARAMETERS.items()}

#: seconds of track after the stroke ends (2 t1) that a replay covers
SETTLE = 0.2
#: a replay's implicit-step iterations: enough that a step converges instead of being
#: rejected and halved, a discrete choice that would make the track jump as parameters move
REPLAY_ITERATIONS = 40


class ReplayError(RuntimeError):
    """A replay's solve failed (the message carries the solver's diagnosis)."""


def canonical(name: str) -> str | None:
    """The fit name of ``name`` (fit name or scene key), None if it is not a fit parameter."""
    if name in PARAMETERS:
        return name
    return ALIASES.get(name)


def scene_value(sc: Scenario, name: str) -> float | None:
    """The scene's value of fit parameter ``name``; None when the scene has no such parameter
    (a fence damping ratio on a stiff fence)."""
    if name == "mu_belt":
        return sc.conveyor.mu_belt
    if name == "mu_fence":
        return sc.contact.mu_fence
    if name in ("k_p", "b_p"):
        return getattr(sc.contact, name)
    if name == "fence.damping_ratio":
        return None if sc.fence is None else sc.fence.damping_ratio
    raise KeyError(name)


def with_values(sc: Scenario, values: dict[str, float]) -> Scenario:
    """``sc`` with the fit parameters set to ``values``."""
    conveyor, contact, fence = sc.conveyor, sc.contact, sc.fence
    for name, v in values.items():
        if name == "mu_belt":
            conveyor = replace(conveyor, mu_belt=float(v))
        elif name == "fence.damping_ratio":
            fence = replace(fence, damping_ratio=float(v))
        else:
            contact = replace(contact, **{name: float(v)})
    return replace(sc, conveyor=conveyor, contact=contact, fence=fence)


@dataclass(frozen=True)
class ParcelEvent:
    parcel_id: int
    parcel: ParcelParams
    alpha_k: float
    t1: float
    r_s: float
    t_start: float  # stroke start in bag time [s]

    @property
    def t_end(self) -> float:
        """Length of the replay after the stroke start [s]."""
        return 2.0 * self.t1 + SETTLE


def event_scenario(base: Scenario, ev: ParcelEvent) -> Scenario:
    """The scene's physics with this parcel, this stroke, a fixed end and the series a track
    needs; a fixed-step trapezoidal solve, so a track is a smooth function of the parameters
    (adaptive step sequences would change with them and spoil finite differences), with
    REPLAY_ITERATIONS so that no step is rejected for want of iterations."""
    # the first replay of a process may compile the kernel inside the solve's wall-time
    # budget (minutes on a loaded machine); divergence is caught by the solver's other checks
    solver = replace(
        base.solver,
        max_wall_time=max(base.solver.max_wall_time, 900.0),
        method="trapezoidal",
        max_iterations=max(base.solver.max_iterations, REPLAY_ITERATIONS),
        stop_when_sorted=False,
        t_end=ev.t_end,
    )
    record = ("trajectory", "fence") if base.fence is not None else ("trajectory",)
    return replace(
        base,
        parcel=ev.parcel,
        drive=DriveParams(alpha_k=ev.alpha_k, t1=ev.t1, r_s=ev.r_s),
        solver=solver,
        record=record,
        initial_velocity=None,
    )


def root_moment_factor(sc: Scenario) -> float:
    """Root bending moment per tip deflection [N m / m] of the fence loaded at its tip:
    M = P R_z with w_tip = P R_z^3 / (3 E I1) (uniform) or (2/3) P R_z^3 / (E I1) (constant
    strength taper); the strain gauge's reading in the emulator and the replays alike."""
    f = sc.fence
    i1 = f.height * f.root_thickness**3 / 12.0
    k = 1.5 if f.profile == "constant_strength" else 3.0
    return k * f.youngs_modulus * i1 / f.length**2


def replay(base: Scenario, ev: ParcelEvent, values: dict[str, float] | None = None) -> Track:
    """The sensors' view of ``ev`` on the twin with ``values`` for the fit parameters."""
    sc = event_scenario(with_values(base, values or {}), ev)
    res = simulate(sc)
    if not res.success:
        raise ReplayError(f"parcel {ev.parcel_id}: replay failed: {res.diagnosis}")
    s = res.series
    p = ev.parcel
    phi = s["phi"]
    x, y = geometric_centre(s["x"], s["y"], phi, p.cog_offset_x, p.cog_offset_y)
    # before the stroke the parcel rides the belt: prepend the straight line
    v = sc.conveyor.belt_speed
    lead = 5.0
    t = np.concatenate(([-lead], s["t"]))
    x = np.concatenate(([x[0] - v * lead], x))
    y = np.concatenate(([y[0]], y))
    yaw = np.concatenate(([phi[0]], phi))
    if sc.fence is not None:
        t_f = s["t_fence"]
        moment = root_moment_factor(sc) * s["tip_deflection"]
    else:
        t_f = moment = np.zeros(0)
    return Track(t=t, x=x, y=y, yaw=yaw, t_fence=t_f, moment=moment, t_end=ev.t_end)
