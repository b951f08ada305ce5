"""The single unit's swept-sector guard (ROS-free): the controller's planning
(:class:`fence_sorter.line.one_unit.UnitTraffic` over the line's guard) against the plant, the
one-fence line's own check of its swept sector (OverlapWarning)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from fence_sorter.capacity import LoadRequest, Planner, PlannerConfig
from fence_sorter.codes import OutcomeCode
from fence_sorter.inputs import ParcelSpec, StrokeCommand
from fence_sorter.line import LineConfig, SortingLine
from fence_sorter.line.one_unit import UnitTraffic, decision_time, decline_reason, unscanned
from fence_sorter.line.routing import SECTOR_OCCUPIED, Booking, track_hits_sector
from fence_sorter.line.types import Outcome, OverlapWarning
from fence_sorter.scene import load_scene
from fence_sorter.stream import StreamConfig, generate

SCAN_X = -3.0
SCENE = "impact_flexible"


@pytest.fixture(scope="module")
def base():
    return load_scene(SCENE).scenario


@pytest.fixture(scope="module")
def warm(base):
    """A planner warmed on the default stream's classes (its cache is copied per run)."""
    planner = Planner(base, PlannerConfig())
    stream = generate(StreamConfig.from_yaml("default"), base.conveyor.belt_speed, count=200)
    planner.warm_up([s.to_parcel_params() for s in stream if s.divert], 10.0)
    return planner


def fresh(base, warm) -> Planner:
    planner = Planner(base, PlannerConfig())
    planner.cache = dict(warm.cache)
    planner.record = {k: list(v) for k, v in warm.record.items()}
    return planner


def run_line(base, planner: Planner, stream: list[ParcelSpec], guarded: bool) -> dict:
    """The controller's loop on the plant: each parcel scanned at SCAN_X, each divert one
    planned at its decision time (with or without the guard), commands to the line."""
    sl = SortingLine(LineConfig.from_scenario(base))
    v = base.conveyor.belt_speed
    traffic = UnitTraffic.of_scenario(base, SCAN_X)
    pending: list[ParcelSpec] = []
    outcomes: dict[int, Outcome] = {}
    warnings: list[OverlapWarning] = []
    declined: dict[str, int] = {}
    strokes = 0
    t, i, dt = 0.0, 0, 0.01
    while len(outcomes) < len(stream) and t < 300.0:
        t += dt
        while i < len(stream) and 0.5 + stream[i].arrival_time <= t:
            spec = replace(stream[i], scan_time=0.5 + stream[i].arrival_time)
            spec = replace(spec, scan_position_x=SCAN_X)
            i += 1
            sl.add_parcel(spec, t)
            traffic.scanned(spec)
            if spec.divert:
                pending.append(spec)
        while pending and decision_time(pending[0], v, planner.config) <= t:
            spec = pending.pop(0)
            req = LoadRequest(spec.parcel_id, spec.to_parcel_params(), spec.scan_time, SCAN_X)
            if guarded:
                plan = traffic.plan(planner, req, t)
            else:
                plan = planner.plan(req, t, commit=False)
            ev = plan.evaluation
            if plan.feasible:
                planner.busy_until = plan.end_time
                alpha_k = planner.config.alpha_k
                traffic.book(spec.parcel_id, plan.start_time, plan.end_time, alpha_k)
                strokes += 1
            else:
                why = decline_reason(plan)
                declined[why] = declined.get(why, 0) + 1
            cmd = StrokeCommand(
                spec.parcel_id, r_s=ev.r_s if ev else 0.0, t1=ev.t1 if ev else 0.5,
                alpha_k=planner.config.alpha_k, feasible=plan.feasible, reason=plan.reason,
            )  # fmt: skip
            assert sl.command(cmd, t).accepted
        traffic.prune(t)
        for e in sl.advance(t):
            if isinstance(e, Outcome):
                outcomes[e.parcel_id] = e
            elif isinstance(e, OverlapWarning):
                warnings.append(e)
    assert len(outcomes) == len(stream)
    return {
        "strokes": strokes,
        "sorted": sum(o.code is OutcomeCode.SORTED for o in outcomes.values()),
        "warnings": warnings,
        "declined": declined,
    }


def pair(gap: float) -> list[ParcelSpec]:
    """A divert parcel and a bystander ``gap`` behind it (rear to front), both 0.4 m long."""
    first = ParcelSpec(1, 0.4, 0.3, 0.2, 4.0, lateral_gap=0.05, divert=True)
    second = replace(first, parcel_id=2, divert=False, arrival_time=(0.4 + gap) / 1.0)
    return [first, second]


def test_a_bystander_close_behind_is_never_swept(base, warm) -> None:
    """The bystander 0.2 m behind enters the sector of the stroke the planner picks by
    capacity alone (the plant reports it); the guard refuses that stroke and the plant sees
    no parcel in the sector of what it commands instead (a stroke or a decline naming the
    guard and the bystander)."""
    assert base.conveyor.belt_speed == 1.0  # pair() spaces the parcels for 1 m/s
    stream = pair(0.2)
    plain = run_line(base, fresh(base, warm), stream, guarded=False)
    assert plain["strokes"] == 1
    assert [(w.stroke_parcel_id, w.other_parcel_id) for w in plain["warnings"]] == [(1, 2)]

    planner = fresh(base, warm)
    traffic = UnitTraffic.of_scenario(base, SCAN_X)
    specs = [
        replace(s, scan_time=s.arrival_time, scan_position_x=SCAN_X) for s in stream
    ]  # fmt: skip
    for s in specs:
        traffic.scanned(s)
    now = decision_time(specs[0], 1.0, planner.config)
    req = LoadRequest(1, specs[0].to_parcel_params(), 0.0, SCAN_X)
    plan = traffic.plan(planner, req, now)
    if plan.feasible:  # another stroke: the bystander stays out of its sector
        d = traffic.guard(1, plan.start_time, plan.end_time, planner.config.alpha_k, now)
        assert d.accepted
    else:
        assert decline_reason(plan) == SECTOR_OCCUPIED
        assert plan.reason.startswith(f"{SECTOR_OCCUPIED}: parcel(s) 2 in the swept sector")
    guarded = run_line(base, fresh(base, warm), stream, guarded=True)
    assert guarded["warnings"] == []
    assert guarded["strokes"] + guarded["declined"].get(SECTOR_OCCUPIED, 0) == 1


def test_a_bystander_far_behind_leaves_the_stroke_alone(base, warm) -> None:
    """3 m behind, the bystander is scanned before the decision and is far from the sector:
    the guard takes the stroke the planner picks by capacity, and the plant sorts it."""
    plain = run_line(base, fresh(base, warm), pair(3.0), guarded=False)
    guarded = run_line(base, fresh(base, warm), pair(3.0), guarded=True)
    assert plain["warnings"] == guarded["warnings"] == []
    assert guarded["strokes"] == guarded["sorted"] == plain["sorted"] == 1


def test_parcels_not_yet_scanned_bound_the_stroke(base) -> None:
    """The region of the parcels not scanned at the decision: its front reaches the sector's
    nearest point, the axis (x0 = 0), (0 - scan line) / v after the decision; a stroke ending
    before that is clear of it, one ending 0.2 s after is not."""
    v, width = base.conveyor.belt_speed, base.conveyor.width
    region = unscanned(SCAN_X, 10.0, width, v)
    t_in = 10.0 + (0.0 - SCAN_X) / v

    def stroke(start: float, end: float) -> Booking:
        return Booking(0, 1, start, end, math.radians(40.0), 1.2, 0.0, False)

    assert not track_hits_sector(region, stroke(t_in - 1.0, t_in - 0.01), width)
    assert track_hits_sector(region, stroke(t_in - 1.0, t_in + 0.2), width)


@pytest.mark.parametrize("rate", [2800.0, 7200.0])
def test_the_guarded_plans_cause_no_intrusion_on_a_dense_stream(base, warm, rate) -> None:
    """40 parcels of the default stream at 2800 and 7200 pcs/h: the planner alone commands
    strokes whose sectors other parcels enter (the plant's OverlapWarning); the guarded one
    none, declining the other divert parcels as sector_occupied (at 7200 pcs/h, 0.3 m apart,
    each of them: the sector reaches 1.2 m along the belt)."""
    cfg = replace(StreamConfig.from_yaml("default"), rate_pcs_h=rate)
    stream = generate(cfg, base.conveyor.belt_speed, count=40)
    divert = sum(s.divert for s in stream)
    plain = run_line(base, fresh(base, warm), stream, guarded=False)
    guarded = run_line(base, fresh(base, warm), stream, guarded=True)
    assert len(plain["warnings"]) >= 5
    assert guarded["warnings"] == []
    assert guarded["strokes"] + sum(guarded["declined"].values()) == divert
    assert guarded["declined"].get(SECTOR_OCCUPIED, 0) > 0
    if rate < 3000.0:  # room for strokes clear of the other parcels for most divert ones
        assert guarded["sorted"] >= 0.75 * divert
