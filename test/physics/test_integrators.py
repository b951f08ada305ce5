"""The time integrators converge at their nominal order on a smooth scene (no ROS, fast).

Smooth scene: impact_flexible with frictionless belt and fence and an elastic contact law
(mu1 = mu2 = b_p = 0): between the located contact onset and release the motion is smooth, so
the order of the schemes is visible in the end state. Observed orders come from three
successive step halvings (Richardson: log2 |y(2h) - y(h)| / |y(h) - y(h/2)|), no reference run.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fence_sorter.physics import kernel as K
from fence_sorter.physics.simulate import SortingModel, simulate
from fence_sorter.physics.stepper import Failure, Stepper, generalized_alpha_coefficients
from fence_sorter.scene import load_scene

SMOOTH = load_scene(
    "impact_flexible",
    [
        "conveyor.mu_belt=0",
        "contact.mu_fence=0",
        "contact.b_p=0",
        "solver.t_end=0.6",
        "solver.stop_when_sorted=false",
    ],
).scenario


def _end_state(**solver) -> np.ndarray:
    sc = replace(SMOOTH, solver=replace(SMOOTH.solver, **solver), record=("trajectory", "fence"))
    r = simulate(sc)
    assert r.success, r.diagnosis
    assert r.events >= 2  # contact onset and release were located
    s = r.series
    return np.array([s["x"][-1], s["y"][-1], s["vx"][-1], s["vy"][-1], s["tip_deflection"][-1]])


@pytest.mark.parametrize("method", ["trapezoidal", "generalized_alpha"])
def test_fixed_step_schemes_are_second_order(method):
    ends = [_end_state(method=method, dt=dt) for dt in (1e-3, 5e-4, 2.5e-4)]
    d1 = np.abs(ends[0] - ends[1])
    d2 = np.abs(ends[1] - ends[2])
    orders = np.log2(d1[:4] / d2[:4])  # the load's position and velocity
    assert np.all(orders > 1.8), orders
    assert np.all(orders < 2.3), orders


def test_adaptive_error_follows_its_tolerance():
    """On a flexible fence the local error per step is held at rtol (rtol / 1e-4)^(1/2)
    below the default (tolerance proportionality, ``kernel.tolerance_scale``) and the step in a
    contact at dt_max (rtol / 1e-4)^(1/2): h ~ rtol^(1/2), so the global error ~ rtol (the plain
    rtol^(2/3) of a second-order scheme is a slope below 0.75)."""
    ref = _end_state(method="trapezoidal", dt=2.5e-5)
    errors, steps = [], []
    for rtol in (1e-4, 1e-6):
        sc = replace(SMOOTH, solver=replace(SMOOTH.solver, method="adaptive", rtol=rtol))
        errors.append(np.abs(_end_state(method="adaptive", rtol=rtol) - ref)[:2].max())
        steps.append(simulate(replace(sc, record=())).steps)
    slope = math.log10(errors[0] / errors[1]) / 2.0
    assert 0.85 < slope < 1.2, (errors, slope)
    assert steps[1] > steps[0]


def test_generalized_alpha_coefficients():
    """Chung-Hulbert: second order (gamma = 1/2 - am + af), unconditionally stable."""
    for rho in (0.0, 0.5, 0.8, 1.0):
        am, af, beta, gamma = generalized_alpha_coefficients(rho)
        assert gamma == pytest.approx(0.5 - am + af)
        assert beta == pytest.approx(0.25 * (0.5 + gamma) ** 2)
        assert am <= af <= 0.5
    # rho_inf = 1: the average-acceleration (trapezoidal) Newmark rule
    assert generalized_alpha_coefficients(1.0) == pytest.approx((0.5, 0.5, 0.25, 0.5))


@pytest.mark.parametrize("rho_inf", [1.0, 0.6, 0.0])
def test_generalized_alpha_damps_the_top_fence_mode_by_rho_inf(rho_inf):
    """No structural damping, drive at rest after its cycle, no contact: the top mode
    (omega h >> 1) keeps its amplitude at rho_inf = 1 and loses it at the rate rho_inf per step
    otherwise; mode 1 (omega h ~ 0.2) loses under 10 % over the same 40 steps (the dissipation
    targets the top of the band). The solve loop's own steps, from modal amplitudes set after
    the fence cycle with accelerations consistent with them."""
    sc = load_scene(
        "impact_flexible",
        [
            "fence.damping_ratio=0",
            "drive.r_s=-3",
            "solver.method=generalized_alpha",
            "solver.dt=2e-3",
            f"solver.rho_inf={rho_inf}",
        ],
    ).scenario
    model = SortingModel(sc)
    m = model.n_modes
    h = sc.solver.dt
    assert model.omega[-1] * h > 100.0 and model.omega[0] * h < 0.3
    s = Stepper(model)
    assert s.advance(2.0 * sc.drive.t1 + 0.05)  # the drive is at rest from 2 t1
    i = int(s.counters[0].cur)
    assert (
        s.resultant_rows[i, 0]["fence_n"] == 0.0 and s.modal_forces[i].max() == 0.0
    )  # no load on the modes
    s.states[i, 6:] = 0.0
    s.states[i, 6] = 1e-3  # mode 1
    s.states[i, 6 + m - 1] = 1e-6  # top mode
    K.loop._accelerations(s.loop_model, K.loop.loop_rows(s._loop_arrays()[1]).trial[i], 0.0)
    t0 = s.t
    amp1, top = [], []
    for _ in range(40):
        assert s.step() is None and s.running
        y = s.y
        amp1.append(math.hypot(y[6], y[6 + m] / model.omega[0]))
        top.append(math.hypot(y[6 + m - 1], y[6 + 2 * m - 1] / model.omega[-1]))
    assert s.t - t0 == pytest.approx(40 * h)  # 40 full fixed steps
    assert amp1[-1] == pytest.approx(1e-3, rel=0.1)  # mode 1 rings on
    if rho_inf == 1.0:
        assert top[-1] == pytest.approx(top[0], rel=0.2)
    else:
        rate = (top[-1] / top[9]) ** (1.0 / 30.0)
        assert rate <= rho_inf + 0.05, rate  # spectral radius -> rho_inf as omega h -> inf


def test_modal_truncation_keeps_the_answer_and_drops_the_stiff_modes():
    full = SortingModel(replace(SMOOTH, fence_modes=None))
    cut = SortingModel(replace(SMOOTH, fence_modes=4))
    assert cut.n_modes == 4 < full.n_modes
    assert cut.omega.max() < 0.1 * full.omega.max()
    a = simulate(replace(SMOOTH, record=()), full)
    b = simulate(replace(SMOOTH, fence_modes=4, record=()), cut)
    assert b.peak_contact_force == pytest.approx(a.peak_contact_force, rel=2e-3)
    assert b.y_max == pytest.approx(a.y_max, abs=1e-3)


def test_stepping_in_chunks_is_the_same_solve():
    """The soft-real-time simulator advances a solve in publish-period chunks
    (Stepper.advance) or one accepted point at a time (Stepper.step): neither changes the
    steps taken."""
    model = SortingModel(SMOOTH)
    whole = Stepper(model)
    assert whole.advance() is False and whole.status == "finished"
    chunked = Stepper(model)
    t, alive = 0.0, True
    while alive:
        t += 0.02
        alive = chunked.advance(t)
        if alive:
            assert chunked.t >= t - 1e-12
    single = Stepper(model)
    times = [single.t]
    while single.running:
        assert single.step() is None
        assert single.t > times[-1]
        times.append(single.t)
    for other in (chunked, single):
        assert other.status == "finished"
        assert other.counters[0].n_steps == whole.counters[0].n_steps == len(times) - 1
        assert other.t == whole.t
        np.testing.assert_array_equal(other.y, whole.y)


@pytest.mark.parametrize(
    ("scene", "sets"),
    [
        # E2 push whose leading corner slides off the fence tip (slide-off event, tip contact)
        ("positioned_stiff", []),
        # the stability campaign's 5 mm grazing case: a few-ms contact at the fence tip
        (
            "arbitrary_stiff",
            [
                "fence.length=1.4",
                "drive.alpha_k_deg=35",
                "drive.t1=0.7",
                "conveyor.belt_speed=1.75",
                "parcel.length_a=0.1",
                "parcel.width_b=0.1",
                "parcel.lateral_gap=0.6",
                "parcel.yaw_deg=0",
                "parcel.cog=centre",
                "drive.r_s=0.5623855079124983",
            ],
        ),
    ],
)
def test_adaptive_default_resolves_short_and_sliding_off_contacts(scene, sets):
    """The default adaptive solve's peak contact force agrees with a fine fixed-step solve
    (dt = 2e-5 s) to 2e-3: contacts shorter than a step are not stepped over (time-to-contact
    step bound) and a corner sliding off the tip is an event, the step ending just before it."""
    default = simulate(load_scene(scene, sets).scenario)
    fine = simulate(
        load_scene(scene, [*sets, "solver.method=trapezoidal", "solver.dt=2e-5"]).scenario
    )
    assert default.success and fine.success
    assert fine.peak_contact_force > 1.0
    assert default.peak_contact_force == pytest.approx(fine.peak_contact_force, rel=2e-3)


def test_the_sorting_line_crossing_ends_a_step():
    """Belt friction ends where C_s crosses y0 = s: the step ends on the crossing, so the final
    pose after 0.8 s of flight off the belt converges (it was 4 cm off when friction acted for
    the rest of the crossing step)."""
    default = simulate(load_scene("impact_flexible").scenario)
    fine = simulate(
        load_scene("impact_flexible", ["solver.method=trapezoidal", "solver.dt=1e-4"]).scenario
    )
    assert default.sorted and fine.sorted
    for key in ("x", "y"):
        assert default.series[key][-1] == pytest.approx(fine.series[key][-1], abs=3e-3)
    assert default.exit_speed_y == pytest.approx(fine.exit_speed_y, rel=1e-3)


@pytest.mark.parametrize("method", ["trapezoidal", "generalized_alpha"])
def test_schemes_stay_second_order_under_coupled_belt_slip(method):
    """A parcel sliding and spinning on the belt (no fence): the elliptic friction law turns the
    wrench smoothly, so both schemes must keep order 2 (generalized-alpha was first order while
    it applied the end-of-step belt wrench at its alpha point)."""
    from fence_sorter.physics.params import ConveyorParams, DriveParams, ParcelParams, SolverParams
    from fence_sorter.physics.simulate import Scenario

    def end(dt: float) -> np.ndarray:
        sc = Scenario(
            conveyor=ConveyorParams(belt_speed=1.5, mu_belt=0.5),
            parcel=ParcelParams(length_a=0.3, width_b=0.2, mass=4.0, lateral_gap=0.2),
            drive=DriveParams(r_s=-3.0, t1=0.3),
            initial_velocity=(0.2, 0.6, 4.0),  # slipping and spinning until t ~ 0.25 s
            solver=SolverParams(method=method, t_end=0.1, dt=dt),
            record=("trajectory",),
        )
        s = simulate(sc).series
        return np.array([s[k][-1] for k in ("x", "y", "phi", "vx", "vy", "phidot")])

    ends = [end(dt) for dt in (2e-3, 1e-3, 5e-4)]
    order = math.log2(np.abs(ends[0] - ends[1]).max() / np.abs(ends[1] - ends[2]).max())
    assert 1.8 < order < 2.3, order


class FakeClock:
    """A wall clock that moves only when told to (``tick`` per reading, ``pause`` by hand)."""

    def __init__(self, tick: float = 0.0):
        self.now, self.tick = 0.0, tick

    def __call__(self) -> float:
        self.now += self.tick
        return self.now


def test_wall_time_limit_counts_stepping_not_the_pauses_between_chunks():
    """A soft-real-time caller pauses between chunks; solver.max_wall_time must only count the
    time spent stepping (else a real-time stroke longer than the limit would be cut off)."""
    sc = replace(SMOOTH, solver=replace(SMOOTH.solver, max_wall_time=0.3))
    clock = FakeClock()
    stepper = Stepper(SortingModel(sc), clock=clock)
    t = 0.0
    while stepper.advance(t):
        clock.now += 0.1  # a pause: 6 chunks, 0.6 s of pauses in all, twice the limit
        t += 0.1
    assert stepper.diagnosis is None and stepper.status == "finished"
    assert stepper.t == pytest.approx(0.6)


def test_wall_time_limit_stops_a_solve_that_steps_too_long():
    """Each solve-loop call reads the clock twice: at 0.05 s per reading the time spent
    stepping passes the 0.3 s limit within a few calls; the solve fails with a typed
    diagnosis at the point it had reached, and simulate reports it."""
    sc = replace(SMOOTH, solver=replace(SMOOTH.solver, max_wall_time=0.3))
    stepper = Stepper(SortingModel(sc), clock=FakeClock(tick=0.05))
    while stepper.step() is None and stepper.running:
        pass
    d = stepper.diagnosis
    assert stepper.status == "failed" and d.kind is Failure.WALL_TIME_LIMIT
    assert d.value == 0.3 and d.t == stepper.t and 0.0 < d.t < 0.6
    assert stepper.busy > 0.3 and 1 <= stepper.counters[0].n_steps <= 7  # ~0.05 s per step
    assert str(d) == d.text == f"wall-time limit 0.3 s reached at t = {d.t:.4f} s"
    r = stepper.result()
    assert not r.success and r.diagnosis == d.text and r.sim_time == d.t
    with pytest.raises(RuntimeError, match="failed"):
        stepper.step()


def test_oscillation_step_caps_only_lightly_damped_contacts() -> None:
    """kernel.oscillation_step linearises law (16) at (D, D'): stiffness 4 k D^3 + 2 b D D',
    damping b D^2 (b = b_p m^0.4) on the load's mass. Undamped: omega h = 10 sqrt(rtol)
    exactly; the paper's b_p at a pushing contact's depth (zeta > OSC_ZETA): no cap; the cap
    starts where zeta = b D^2 / (2 sqrt(K m)) falls below OSC_ZETA."""
    from fence_sorter.physics import kernel as K

    sc = load_scene("positioned_stiff").scenario
    md = SortingModel(sc)
    m, k = md.mass, sc.contact.k_p
    out = K.zero_slots()
    assert K.oscillation_step(md.P, out, 1e-4) == math.inf  # no contact
    out[1]["active"], out[1]["d"], out[1]["ddot"] = 1.0, 0.0139, 0.0  # N ~ 65 N
    b = sc.contact.b_p * m**0.4
    stiff = 4.0 * k * 0.0139**3
    zeta = b * 0.0139**2 / (2.0 * math.sqrt(stiff * m))
    assert zeta > 0.1  # the paper's contact is well damped: not capped
    assert K.oscillation_step(md.P, out, 1e-4) == math.inf
    undamped = SortingModel(load_scene("positioned_stiff", ["contact.b_p=0"]).scenario)
    h = K.oscillation_step(undamped.P, out, 1e-4)
    assert h * math.sqrt(stiff / m) == pytest.approx(10.0 * math.sqrt(1e-4), rel=1e-12)
    # k_p x1000 at the same force (D smaller by 1000^0.25): zeta ~ 0.003, capped
    stiffer = SortingModel(load_scene("positioned_stiff", ["contact.k_p=1.72e12"]).scenario)
    d = 0.0139 / 1000.0**0.25
    out[1]["d"] = d
    stiff = 4.0 * 1.72e12 * d**3
    assert b * d * d / (2.0 * math.sqrt(stiff * m)) < K.OSC_ZETA
    h = K.oscillation_step(stiffer.P, out, 1e-5)
    assert h * math.sqrt(stiff / m) == pytest.approx(10.0 * math.sqrt(1e-5), rel=1e-12)
    # the damping ratio's boundary: just above it no cap, just below it the cap
    for scale, capped in ((1.01, False), (0.99, True)):
        d_b = (2.0 * K.OSC_ZETA * scale * math.sqrt(4.0 * k * m) / b) ** 2  # zeta ~ sqrt(D)
        out[1]["d"] = d_b
        assert (K.oscillation_step(md.P, out, 1e-4) < math.inf) == capped
