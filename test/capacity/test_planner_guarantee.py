"""The planner's guarantee: a stroke it returns feasible meets (10)-(12) on the plant itself
(the scene's flexible fence at its own solver settings, the exact parcel), at the nominal
parcel and at each corner of its uncertainty set; the corners and the deadline by hand."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from fence_sorter.capacity import LoadRequest, Planner, PlannerConfig, evaluate_stroke
from fence_sorter.capacity.uncertainty import CORNERS, UncertaintySet
from fence_sorter.codes import OutcomeCode
from fence_sorter.physics.params import ParameterError, ParcelParams
from fence_sorter.scene import load_scene
from fence_sorter.stream import load_stream

SCAN_X = -3.0
W_DOP, A_NDOP, YDOT_DOP = 2.4, 300.0, 2.5  # (10)-(12), paper section 3


@pytest.fixture(scope="module")
def plant():
    """The default scene (flexible PA6 fence) with the belt at 2 m/s."""
    return load_scene("impact_flexible", ["conveyor.belt_speed=2.0"]).scenario


@pytest.fixture(scope="module")
def planned(plant):
    """12 parcels of the mixed stream, each planned on its own (fence free)."""
    stream = load_stream("mixed", plant.conveyor.belt_speed, count=12)
    planner = Planner(plant, PlannerConfig())
    out = []
    for s in stream:
        req = LoadRequest(
            s.parcel_id, s.to_parcel_params(), s.arrival_time, SCAN_X, s.mu_belt, s.mu_fence
        )
        out.append((req, planner.plan(req, s.arrival_time, commit=False)))
    return planner, out


def within_limits(ev) -> bool:
    return (
        ev.sorted
        and ev.impact_speed <= W_DOP
        and ev.peak_accel <= A_NDOP
        and ev.exit_speed <= YDOT_DOP
    )


def test_verified_strokes_meet_the_limits_on_the_plant(plant, planned) -> None:
    """Each feasible plan, simulated on the scene's own settings with the exact parcel,
    sorts it within w_dop, a_Ndop and ydot_dop; a decline names a constraint of (7)-(12)."""
    planner, plans = planned
    feasible = [(req, plan) for req, plan in plans if plan.feasible]
    assert len(feasible) >= 8, [plan.reason for _, plan in plans]
    for req, plan in feasible:
        ev = plan.evaluation
        got = evaluate_stroke(
            plant, req.parcel, ev.r_s, ev.t1, planner.config.alpha_k, gap=0.1,
            mu_belt=req.mu_belt, mu_fence=req.mu_fence,
        )  # fmt: skip
        assert within_limits(got), (req.parcel, got.diagnosis)
        assert plan.tried[-1] is ev and plan.evaluations >= 1 + len(planner.corners)
    for _, plan in plans:
        if not plan.feasible:
            assert plan.code is OutcomeCode.NO_FEASIBLE_COMMAND and plan.violated, plan.reason
            assert set(plan.violated) <= {7, 8, 9, 10, 11, 12}


def test_verified_strokes_meet_the_limits_at_every_corner(plant, planned) -> None:
    """The same strokes on the plant at each corner of the uncertainty set."""
    planner, plans = planned
    box = planner.config.uncertainty
    mu1, mu2 = plant.conveyor.mu_belt, plant.contact.mu_fence
    for req, plan in [x for x in plans if x[1].feasible][:4]:
        ev = plan.evaluation
        for corner in box.corners():
            p, m1, m2 = box.apply(corner, req.parcel, mu1, mu2, plant.conveyor.width)
            got = evaluate_stroke(
                plant, p, ev.r_s, ev.t1, planner.config.alpha_k, gap=0.1,
                mu_belt=m1, mu_fence=m2,
            )  # fmt: skip
            assert within_limits(got), (corner.name, req.parcel, got.diagnosis)
            worst = ev.extra["worst"]
            assert got.exit_speed <= worst["exit_speed"] + 0.02  # planning tolerances
            assert got.peak_accel <= worst["peak_accel"] * 1.03


def test_a_stroke_failing_at_a_corner_is_not_feasible(plant) -> None:
    """A limit met at the nominal parcel but not over its uncertainty set: the stroke is
    not feasible, naming the corner and the constraint; with no uncertainty it is."""
    p = ParcelParams(0.4, 0.3, 0.3, 15.0, 0.0, 0.0, 0.25, 0.0)
    mus = plant.conveyor.mu_belt, plant.contact.mu_fence
    plan = Planner(plant, PlannerConfig()).plan(LoadRequest(1, p, 0.0, SCAN_X), 0.0)
    assert plan.feasible, plan.reason
    ev = plan.evaluation
    worst = ev.extra["worst"]["exit_speed"]
    assert worst > ev.exit_speed
    # (12)'s limit between the nominal exit speed and the worst corner's
    cfg = PlannerConfig()
    cfg = replace(cfg, profile=replace(cfg.profile, ydot_dop=0.5 * (ev.exit_speed + worst)))
    verdict, _ = Planner(plant, cfg).verify(p, *mus, (ev.r_s, ev.t1))
    assert not verdict.feasible and verdict.violated == (12,)
    assert "corner of the uncertainty set" in verdict.diagnosis
    assert verdict.margins[12] < 0.0  # met at the nominal parcel
    exact = replace(cfg, uncertainty_mass=0.0, uncertainty_mu=0.0, uncertainty_size=0.0)
    verdict, _ = Planner(plant, exact).verify(p, *mus, (ev.r_s, ev.t1))
    assert verdict.feasible


def test_uncertainty_corners_by_hand() -> None:
    box = UncertaintySet(mass=0.05, mu=0.05, size=0.005)
    p = ParcelParams(0.4, 0.3, 0.3, 10.0, 0.0, 0.0, 0.398, 0.0)
    heavy = next(c for c in CORNERS if c.name == "slippery heavy")
    q, m1, m2 = box.apply(heavy, p, 0.65, 0.35, 0.7)
    assert q.mass == pytest.approx(10.5) and (m1, m2) == pytest.approx((0.60, 0.30))
    assert (q.length_a, q.width_b) == pytest.approx((0.395, 0.305))
    # 5 mm wider no longer fits beside a 0.398 m gap on a 0.7 m belt: moved to the fence side
    assert q.lateral_gap == pytest.approx(0.7 - 0.305)
    assert len(box.corners()) == 4
    # the mass alone uncertain: the corners differing only in mu or size are one
    assert [c.mass for c in UncertaintySet(0.05, 0.0, 0.0).corners()] == [1, -1]
    assert UncertaintySet(0.0, 0.0, 0.0).corners() == ()
    with pytest.raises(ParameterError, match=r"controller.uncertainty_mu must be in"):
        PlannerConfig.from_mapping({"uncertainty_mu": 0.9})
    cfg = PlannerConfig.from_mapping({"uncertainty_size": 0.002, "uncertainty_mass": 0.1})
    assert cfg.uncertainty == UncertaintySet(0.1, 0.05, 0.002)


def test_deadline_is_the_last_start_at_the_real_time_factor(plant) -> None:
    """The front reaches R_s_max = 1 m from the scan line at -3 m in 4 m / v = 2 s; less
    start_margin 0.1 s and, at rtf 4, a quarter of that in wall time, less the margin; never
    less than min_planning_time."""
    planner = Planner(plant, PlannerConfig(deadline_margin=0.02))
    req = LoadRequest(1, ParcelParams(), scan_time=10.0, scan_position_x=SCAN_X)
    d = planner.deadline(req, now=10.5, rtf=4.0, wall_now=100.0)
    assert d == pytest.approx(100.0 + (10.0 + 4.0 / 2.0 - 0.1 - 10.5) / 4.0 - 0.02)
    assert math.isfinite(planner.deadline(req, now=10.5, rtf=0.0, wall_now=0.0))
    # unpaced (50x: 28 ms of wall time left): min_planning_time, 0.2 s, at the least
    assert planner.deadline(req, now=10.5, rtf=50.0, wall_now=100.0) == pytest.approx(100.2)
