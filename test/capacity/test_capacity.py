"""Capacity (1)-(2), constraint margins (7)-(12), stroke evaluation and the planner."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
import yaml

from fence_sorter.capacity import (
    ConstraintProfile,
    LoadRequest,
    Planner,
    PlannerConfig,
    capacity,
    evaluate_stroke,
    pitch,
    planning_scenario,
    scraping_time,
    stroke_capacity,
)
from fence_sorter.codes import OutcomeCode, decline_code
from fence_sorter.physics.params import ParameterError, ParcelParams
from fence_sorter.scene import load_scene

REPO = __import__("pathlib").Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def base():
    return load_scene("positioned_stiff").scenario


# -- (1) and (2) by hand -----------------------------------------------------------------------
def test_capacity_and_pitch_by_hand() -> None:
    # v = 2 m/s, t1 = 0.5 s, R_s = -0.4 m: t_z = 2 * 0.5 + 0.4 / 2 = 1.2 s, v t_z = 2.4 m
    assert scraping_time(2.0, 0.5, -0.4) == pytest.approx(1.2)
    assert pitch(2.0, 0.5, -0.4, a_max=0.7, gap=0.3) == pytest.approx(2.4)
    assert stroke_capacity(2.0, 0.5, -0.4, 0.7, 0.3) == pytest.approx(3600 * 2 / 2.4)  # 3000
    # v t_z = 0.5 * (0.4 + 0) = 0.2 m < A_max + Delta = 0.8 m: Delta_c = 0.8 m
    assert pitch(0.5, 0.2, 0.0, a_max=0.7, gap=0.1) == pytest.approx(0.8)
    assert capacity(0.5, 0.8) == pytest.approx(2250.0)
    # the boundary v t_z == A_max + Delta takes the "otherwise" branch (same value)
    assert pitch(1.0, 0.4, 0.0, a_max=0.7, gap=0.1) == pytest.approx(0.8)


def test_capacity_rejects_bad_input() -> None:
    with pytest.raises(ParameterError, match="delta_c"):
        capacity(1.0, 0.0)
    with pytest.raises(ParameterError, match="v must be"):
        scraping_time(0.0, 0.5, 0.0)


# -- evaluate_stroke ---------------------------------------------------------------------------
def test_evaluation_margins_match_the_simulated_figures(base) -> None:
    sc = planning_scenario(base)
    parcel = base.parcel
    ev = evaluate_stroke(sc, parcel, 0.7, 0.9, math.radians(40.0))
    v, s = base.conveyor.belt_speed, base.conveyor.width
    assert ev.sorted and ev.feasible, ev.diagnosis
    assert ev.margins[7] == pytest.approx((parcel.length_a - 0.7) / v - 0.9)
    assert ev.margins[8] == pytest.approx(s - ev.y_max)
    assert ev.margins[10] == pytest.approx(ev.impact_speed - 2.4)
    assert ev.margins[11] == pytest.approx(ev.peak_accel - 300.0)
    assert ev.margins[12] == pytest.approx(ev.exit_speed - 2.5)
    assert ev.capacity_pcs_h == pytest.approx(stroke_capacity(v, 0.9, 0.7, parcel.length_a, 0.0))
    # the planning settings agree with the scene's own solver on the peak figures
    ref = evaluate_stroke(base, parcel, 0.7, 0.9, math.radians(40.0))
    assert ev.peak_accel == pytest.approx(ref.peak_accel, rel=0.06)
    assert ev.exit_speed == pytest.approx(ref.exit_speed, rel=0.03)
    assert ev.y_max == pytest.approx(ref.y_max, abs=0.01)


def test_infeasible_profile_names_the_constraint(base) -> None:
    sc = planning_scenario(base)
    tight = ConstraintProfile(a_ndop=1.0)  # no push is that gentle
    ev = evaluate_stroke(sc, base.parcel, 0.7, 0.9, math.radians(40.0), tight)
    assert not ev.feasible
    assert 11 in ev.violated
    assert "(11)" in ev.diagnosis
    # every admissible candidate evaluated: no feasible stroke, naming the constraint
    planner = Planner(base, PlannerConfig(profile=tight, max_evaluations=1000))
    plan = planner.plan(LoadRequest(1, base.parcel, 0.0, -3.0), now=0.0)
    assert not plan.feasible and plan.code is OutcomeCode.NO_FEASIBLE_COMMAND
    assert len(plan.tried) == plan.admissible > 6
    assert 11 in plan.violated and "(11) acceleration" in plan.reason
    assert plan.reason.startswith("no feasible stroke")
    # the cap reached with candidates left: the budget ran out, which is not "no stroke"
    capped = Planner(base, PlannerConfig(profile=tight, max_evaluations=6))
    plan = capped.plan(LoadRequest(1, base.parcel, 0.0, -3.0), now=0.0)
    assert not plan.feasible and plan.code is OutcomeCode.NO_STROKE_IN_BUDGET
    assert plan.evaluations == 6 and len(plan.tried) < plan.admissible
    assert decline_code(plan.reason) is OutcomeCode.NO_STROKE_IN_BUDGET
    # a deadline long past: nothing evaluated, the budget ran out
    late = Planner(base, PlannerConfig()).plan(
        LoadRequest(1, base.parcel, 0.0, -3.0), now=0.0, deadline=-math.inf
    )
    assert late.code is OutcomeCode.NO_STROKE_IN_BUDGET and late.evaluations == 0


# -- planner -----------------------------------------------------------------------------------
def test_planner_choice_satisfies_every_constraint_it_reports(base) -> None:
    planner = Planner(base, PlannerConfig(max_evaluations=40))
    loads = [
        ParcelParams(0.4, 0.3, 0.3, 5.0, 0.0, 0.0, 0.1, 0.0),
        ParcelParams(0.2, 0.2, 0.2, 1.0, 0.05, 0.0, 0.3, 0.05),
        ParcelParams(0.7, 0.1, 0.1, 5.0, -0.35, -0.05, 0.0, 0.0),
    ]
    t = 0.0
    for i, p in enumerate(loads):
        plan = planner.plan(LoadRequest(i, p, t, -3.0), now=t)
        assert plan.feasible, plan.reason
        ev = plan.evaluation
        assert ev.feasible and ev.sorted
        assert all(ev.margins[c] <= 0.0 for c in ev.active if not math.isnan(ev.margins[c]))
        assert plan.evaluations <= planner.config.max_evaluations
        # re-simulating the chosen stroke on the exact load gives the same verdict
        again = evaluate_stroke(
            planner.base, p, ev.r_s, ev.t1, ev.alpha_k, gap=planner.config.pitch_gap
        )
        assert again.feasible and again.margins == pytest.approx(ev.margins, nan_ok=True)
        # timing: the command is out before the front reaches R_s, after the previous stroke
        assert plan.start_time >= t + planner.config.start_margin
        assert planner.busy_until == pytest.approx(plan.end_time)
        t += 2.0  # the next load is scanned while the fence may still be busy


def test_planner_respects_the_busy_window_and_the_time_left(base) -> None:
    planner = Planner(base, PlannerConfig())
    p = ParcelParams(0.4, 0.3, 0.3, 5.0)
    first = planner.plan(LoadRequest(1, p, 0.0, -3.0), now=0.0)
    assert first.feasible
    second = planner.plan(LoadRequest(2, p, 0.0, -3.0), now=0.0)  # same arrival: needs later R_s
    if second.feasible:
        assert second.start_time >= first.end_time + planner.config.busy_margin - 1e-9
        assert second.evaluation.r_s > first.evaluation.r_s
    else:
        assert "busy" in second.reason
    # a load whose front is already past R_s_max: too late, no twin evaluation
    late = planner.plan(LoadRequest(3, p, 0.0, 2.0), now=0.0)
    assert not late.feasible and late.reason.startswith("too late") and late.evaluations == 0


def test_planner_class_gives_the_first_candidate_the_exact_load_verifies_it(base) -> None:
    """A load of a class planned before gets the class's stroke first, verified on the load
    itself (nominal and each corner: 1 + 4 evaluations); the same load again is free."""
    planner = Planner(base, PlannerConfig())
    n_corners = len(planner.corners)
    assert n_corners == 4
    p = ParcelParams(0.4, 0.3, 0.3, 5.0, 0.0, 0.0, 0.1, 0.0)
    a = planner.plan(LoadRequest(1, p, 0.0, -3.0), now=0.0, commit=False)
    q = replace(p, mass=5.05, lateral_gap=0.105)
    b = planner.plan(LoadRequest(2, q, 0.0, -3.0), now=0.0, commit=False)
    assert a.feasible and b.feasible
    assert (a.evaluation.r_s, a.evaluation.t1) == (b.evaluation.r_s, b.evaluation.t1)
    assert b.evaluations == 1 + n_corners and len(b.tried) == 1
    again = planner.plan(LoadRequest(3, q, 0.0, -3.0), now=0.0, commit=False)
    assert again.evaluations == 0 and again.cache_hits == 1
    assert again.evaluation == b.evaluation


def test_planner_passes_a_refused_stroke_over_for_the_next_feasible_one(base) -> None:
    """``accept`` refuses a feasible stroke (a line's guard: a parcel in its sector): the plan
    is the next feasible candidate, with its own times; refusing every one declines the load
    and says so; the class keeps its stroke by physics (the first feasible one)."""
    p = ParcelParams(0.4, 0.3, 0.3, 5.0, 0.0, 0.0, 0.1, 0.0)
    free = Planner(base, PlannerConfig(max_evaluations=40))
    first = free.plan(LoadRequest(1, p, 0.0, -3.0), now=0.0, commit=False)
    assert first.feasible and first.refused == 0
    seen: list[tuple[float, float, float, float]] = []

    def not_the_first(ev, start: float, end: float) -> bool:
        seen.append((ev.r_s, ev.t1, start, end))
        return (ev.r_s, ev.t1) != (first.evaluation.r_s, first.evaluation.t1)

    planner = Planner(base, PlannerConfig(max_evaluations=40))
    plan = planner.plan(LoadRequest(1, p, 0.0, -3.0), now=0.0, commit=False, accept=not_the_first)
    assert plan.feasible and plan.refused == 1, plan.reason
    ev = plan.evaluation
    assert ev.feasible and (ev.r_s, ev.t1) != (first.evaluation.r_s, first.evaluation.t1)
    # the times handed to accept are the stroke's: front at R_s, then 2 t1
    r_s, t1, start, end = seen[0]
    assert start == pytest.approx((r_s + 3.0) / planner.v) and end == pytest.approx(start + 2 * t1)
    assert plan.start_time == pytest.approx((ev.r_s + 3.0) / planner.v)
    assert plan.end_time == pytest.approx(plan.start_time + 2.0 * ev.t1)
    assert planner.chosen[planner.class_key(LoadRequest(1, p, 0.0, -3.0))] == (
        first.evaluation.r_s,
        first.evaluation.t1,
    )
    none = Planner(base, PlannerConfig(max_evaluations=1000))
    refused = none.plan(LoadRequest(1, p, 0.0, -3.0), now=0.0, accept=lambda ev, s, e: False)
    assert not refused.feasible and refused.refused >= 1
    assert "refused" in refused.reason and none.busy_until == -math.inf


def test_lower_friction_gives_no_lower_capacity(base) -> None:
    """Paper, Fig. 4: smaller mu1, mu2 -> higher (here: not lower) capacity."""
    # every candidate in W_t order, the figures exact (the paper's curves): the true first
    cfg = PlannerConfig(
        max_evaluations=400, uncertainty_mass=0.0, uncertainty_mu=0.0, uncertainty_size=0.0
    )
    p = ParcelParams(0.7, 0.1, 0.1, 5.0, -0.35, -0.05, 0.0, 0.0)
    caps = []
    for mu1, mu2 in ((0.65, 0.35), (0.3, 0.15)):
        planner = Planner(base, cfg)
        plan = planner.plan(LoadRequest(1, p, 0.0, -3.0, mu1, mu2), now=0.0)
        assert plan.feasible, plan.reason
        caps.append(plan.evaluation.capacity_pcs_h)
    assert caps[1] >= caps[0]


def test_config_file_and_bad_values() -> None:
    data = yaml.safe_load((REPO / "config" / "controller.yaml").read_text())
    cfg = PlannerConfig.from_mapping(data["controller"]["ros__parameters"])
    assert cfg.alpha_k == pytest.approx(math.radians(40.0))
    assert cfg.profile == ConstraintProfile(2.4, 300.0, 2.5, (7, 8, 9, 10, 11, 12))
    with pytest.raises(ParameterError, match=r"controller.a_ndop must be in"):
        PlannerConfig.from_mapping({"a_ndop": -1.0})
    with pytest.raises(ParameterError, match=r"controller.active_constraints"):
        PlannerConfig.from_mapping({"active_constraints": [7, 13]})
    with pytest.raises(ParameterError, match=r"t1_min .* must not exceed t1_max"):
        PlannerConfig.from_mapping({"t1_min": 1.0, "t1_max": 0.5})
    with pytest.raises(ParameterError, match=r"fence_model must be one of"):
        PlannerConfig.from_mapping({"fence_model": "rubber"})


def test_damage_risk_margins_and_drop_height():
    """Margins 1 - value / limit and the drop height w_n^2 / (2 g) (a free fall from h lands
    at w_n): at the paper's w_dop = 2.4 m/s, h = 0.294 m."""
    from fence_sorter.capacity.constraints import ConstraintProfile, damage_risk

    limits = ConstraintProfile(w_dop=2.4, a_ndop=300.0)
    r = damage_risk(1.2, 450.0, limits)
    assert r.impact_speed_margin == pytest.approx(0.5)
    assert r.accel_margin == pytest.approx(-0.5)  # 50 % over a_Ndop
    at_limit = damage_risk(2.4, 300.0, limits)
    assert at_limit.impact_speed_margin == 0.0 == at_limit.accel_margin
    assert at_limit.drop_height == pytest.approx(0.2936, abs=1e-4)
    assert math.sqrt(2 * 9.81 * r.drop_height) == pytest.approx(1.2)
    none = damage_risk(math.nan, math.nan, limits)
    assert math.isnan(none.impact_speed_margin) and math.isnan(none.drop_height)
