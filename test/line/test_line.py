"""The multi-parcel sorting line (ROS-free): belt ride, strokes stepped with the clock, outcomes.

Scene: impact_flexible's line (flexible PA6 fence, belt 1 m/s); its load (15 kg, 0.4 x 0.3 m at
Delta_s = 0.25 m) with its drive (alpha_k 40 deg, t1 0.35 s, R_s 0.42 m) is sorted.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fence_sorter.codes import BUDGET_REASON
from fence_sorter.line import (
    InputError,
    LineConfig,
    Outcome,
    OutcomeCode,
    OverlapWarning,
    ParcelSpec,
    SortingLine,
    Stage,
    StartMode,
    StrokeCommand,
    in_swept_sector,
)
from fence_sorter.physics.simulate import simulate
from fence_sorter.scene import load_scene

SCENE = load_scene("impact_flexible").scenario
ALPHA_K = math.radians(40.0)
DT = 0.002  # line clock chunk [s] (a 500 Hz pacing loop)


def make_line(**overrides) -> SortingLine:
    sc = load_scene("impact_flexible", [f"{k}={v}" for k, v in overrides.items()]).scenario
    return SortingLine(LineConfig.from_scenario(sc))


def diverging_line() -> SortingLine:
    """Stability case diverging_trapezoidal: the contact iteration cannot converge at any step."""
    overrides = {
        "solver.method": "trapezoidal",
        "contact.k_p": 1e16,
        "solver.dt": 5e-3,
        "solver.min_dt": 1e-3,
    }
    return make_line(**overrides)


def heavy(pid: int, **kw) -> ParcelSpec:
    """The scene's load, scanned at x0 = -1 m at t = 0 unless told otherwise."""
    base = dict(
        length_a=0.4,
        width_b=0.3,
        height=0.3,
        mass=15.0,
        lateral_gap=0.25,
        divert=True,
        scan_time=0.0,
        scan_position_x=-1.0,
    )
    base.update(kw)
    return ParcelSpec(pid, **base)


def stroke(pid: int, **kw) -> StrokeCommand:
    return StrokeCommand(pid, **{"r_s": 0.42, "t1": 0.35, "alpha_k": ALPHA_K, **kw})


def run(line: SortingLine, t_end: float, dt: float = DT, on_step=None) -> list:
    """Advance the line in chunks of dt to t_end; return every event."""
    events = []
    n = round((t_end - line.t) / dt)
    t0 = line.t
    for k in range(1, n + 1):
        events += line.advance(t0 + k * dt)
        if on_step is not None:
            on_step(line)
    return events


def outcomes(events) -> dict[int, Outcome]:
    out: dict[int, Outcome] = {}
    for e in events:
        if isinstance(e, Outcome):
            assert e.parcel_id not in out, f"two outcomes for parcel {e.parcel_id}"
            out[e.parcel_id] = e
    return out


def test_parcel_rides_the_belt_at_belt_speed():
    line = make_line()
    line.add_parcel(heavy(1, divert=False, scan_time=0.5, scan_position_x=-2.0), 0.5)
    line.advance(0.5)
    a = line.snapshot().parcels[0]
    run(line, 1.5)
    b = line.snapshot().parcels[0]
    assert b.stage is Stage.ON_BELT
    assert b.x - a.x == pytest.approx(1.0 * 1.0, abs=1e-12)  # v = 1 m/s for 1 s
    assert (b.y, b.yaw, b.vx, b.vy) == (a.y, a.yaw, 1.0, 0.0)
    # the front follows x_f = scan_position_x + v (t - scan_time)
    assert max(c[0] for c in b.corners) == pytest.approx(-2.0 + 1.0 * (1.5 - 0.5), abs=1e-12)
    # C_s at the gap plus half the width across the belt
    assert b.y == pytest.approx(0.25 + 0.15)


def test_divert_parcel_is_sorted_by_the_same_solve_as_simulate():
    line = make_line()
    line.add_parcel(heavy(1))
    res = line.command(stroke(1))
    assert res.accepted and res.start_time == pytest.approx(1.42)  # front -1 m -> 0.42 m at 1 m/s
    tips, scenario = [], []

    def watch(ln: SortingLine) -> None:
        f = ln.snapshot().fence
        if f.stroke_parcel_id is not None:
            tips.append(abs(f.tip_deflection))
            assert f.from_solve and len(f.node_x) == 11  # 10 elements
        sc = ln.stroke_scenario(1)
        if sc is not None and not scenario:
            scenario.append(sc)

    events = run(line, 3.0, on_step=watch)
    out = outcomes(events)
    assert out[1].code is OutcomeCode.SORTED and out[1].sorted
    # the same Scenario solved in one go by simulate() gives the same figures (same steps)
    ref = simulate(replace(scenario[0], solver=replace(scenario[0].solver, stop_when_sorted=True)))
    assert ref.sorted
    assert scenario[0].drive.r_s == 0.42 and scenario[0].parcel.mass == 15.0
    assert out[1].peak_normal_force == ref.peak_contact_force
    assert out[1].peak_normal_force_stiff == ref.peak_contact_force_stiff
    assert out[1].exit_speed_y == ref.exit_speed_y
    assert out[1].impact_normal_speed == pytest.approx(2.43, abs=0.03)  # the 0.3 m free fall
    # the outcome comes when the line clock passes the crossing of y0 = s (ref.sim_time is the
    # end of the step that crossed it)
    assert abs(out[1].t - (1.42 + ref.sim_time)) <= DT + 5e-3
    # Fig. 11c: the flexible fence cuts N well below N_stiff
    assert out[1].peak_normal_force < 0.5 * out[1].peak_normal_force_stiff
    # the fence bent during the stroke and is back at rest after 2 t1
    assert max(tips) > 1e-3
    f = line.snapshot().fence
    assert f.stroke_parcel_id is None and f.drive_angle == 0.0 and not f.deflection.any()
    assert line.snapshot().parcels == []


def test_not_diverted_parcel_passes_the_line_end():
    line = make_line()
    line.add_parcel(heavy(7, divert=False))
    out = outcomes(run(line, 5.0))
    assert out[7].code is OutcomeCode.NOT_DIVERTED
    # rear (front - A) passes line_end_x = 3 m: front at 3.4 m, t = 4.4 s
    assert out[7].t == pytest.approx(4.4, abs=1e-9)
    assert math.isnan(out[7].peak_normal_force)


def test_overlapping_stroke_is_rejected_and_reported():
    line = make_line()
    line.add_parcel(heavy(1))
    line.add_parcel(heavy(2, scan_position_x=-1.3))  # 0.3 s behind: inside the first cycle
    assert line.command(stroke(1)).accepted
    res = line.command(stroke(2))
    assert not res.accepted and res.code == "fence_busy" and "parcel 1" in res.reason
    dup = line.command(stroke(1))
    assert not dup.accepted and dup.code == "duplicate"
    assert line.command(stroke(99)).code == "unknown_parcel"
    out = outcomes(run(line, 4.0))
    assert out[1].code is OutcomeCode.SORTED
    assert out[2].code is OutcomeCode.REJECTED and "fence busy" in out[2].reason
    # at its point of no return: front at R_s max = 2 m
    assert out[2].t == pytest.approx(1.3 + 2.0, abs=1e-9)


def test_late_command_and_no_command_give_no_command():
    line = make_line()
    line.add_parcel(heavy(1))
    line.add_parcel(heavy(2, scan_position_x=-4.0))
    run(line, 1.6)  # parcel 1's front is at 0.6 m, past R_s = 0.42 m
    res = line.command(stroke(1))
    assert not res.accepted and res.code == "late"
    out = outcomes(run(line, 7.0))
    assert out[1].code is OutcomeCode.NO_COMMAND and "late" in out[1].reason
    assert out[1].t == pytest.approx(3.0, abs=1e-9)  # front at the point of no return, 2 m
    assert out[2].code is OutcomeCode.NO_COMMAND and "no command" in out[2].reason
    assert out[2].t == pytest.approx(6.0, abs=1e-9)
    assert line.command(stroke(1)).code == "parcel_done"


def test_infeasible_command_keeps_the_controllers_reason():
    line = make_line()
    line.add_parcel(heavy(3))
    res = line.command(stroke(3, feasible=False, reason="impact speed 3.1 > 2.4 m/s"))
    assert res.accepted and res.code == "infeasible"
    out = outcomes(run(line, 5.0))
    assert out[3].code is OutcomeCode.NO_FEASIBLE_COMMAND
    assert "impact speed 3.1 > 2.4 m/s" in out[3].reason
    assert out[3].t == 0.0  # at once, not at the line end
    # a planner that ran out of time is not one that found no stroke
    line.add_parcel(heavy(4, scan_time=5.0), 5.0)
    reason = f"{BUDGET_REASON}: 3 of 20 candidates verified by the command's deadline"
    assert line.command(stroke(4, feasible=False, reason=reason), 5.0).accepted
    out = outcomes(run(line, 6.0))
    assert out[4].code is OutcomeCode.NO_STROKE_IN_BUDGET and out[4].reason == reason


def test_start_at_time_uses_the_front_position_then():
    line = make_line()
    line.add_parcel(heavy(1))
    res = line.command(stroke(1, start_mode=StartMode.AT_TIME, start_time=1.42, r_s=0.0))
    assert res.accepted and res.start_time == 1.42
    seen = []
    run(line, 1.5, on_step=lambda ln: seen.append(ln.stroke_scenario(1)))
    sc = next(s for s in seen if s is not None)
    assert sc.drive.r_s == pytest.approx(0.42, abs=1e-12)
    out = outcomes(run(line, 3.0))
    assert out[1].code is OutcomeCode.SORTED


@pytest.mark.parametrize(
    ("change", "key", "field"),
    [
        ({"mass": math.nan}, "non_finite", "mass"),
        ({"lateral_gap": math.inf}, "non_finite", "lateral_gap"),
        ({"mass": -2.0}, "mass", "mass"),
        ({"mass": 0.0}, "mass", "mass"),
        ({"width_b": 0.6}, "wider_than_belt", "width_b"),  # 0.25 + 0.6 > 0.7 m
        ({"length_a": 7.0}, "size", "length_a"),
        ({"cog_offset_x": 0.3}, "cog_offset", "cog_offset_x"),
        ({"mu_belt": -0.1}, "friction", "mu_belt"),
    ],
)
def test_bad_parcel_is_rejected_naming_the_field(change, key, field):
    line = make_line()
    with pytest.raises(InputError) as err:
        line.add_parcel(heavy(1, **change))
    assert err.value.key == key and err.value.field == field
    assert field in str(err.value)
    if key not in ("non_finite", "friction"):
        assert "[" in str(err.value)  # the allowed range
    # the line keeps working
    line.add_parcel(heavy(1))
    assert line.parcels_on_line == 1


def test_duplicate_id_is_rejected_even_after_the_outcome():
    line = make_line()
    line.add_parcel(heavy(1, divert=False))
    with pytest.raises(InputError) as err:
        line.add_parcel(heavy(1))
    assert err.value.key == "duplicate_id"
    run(line, 5.0)
    with pytest.raises(InputError):
        line.add_parcel(heavy(1, scan_time=5.0))


def test_diverging_solve_is_a_solver_failure_with_no_state_past_it():
    # stability case diverging_trapezoidal: the contact iteration cannot converge at any step
    line = diverging_line()
    line.add_parcel(heavy(1))
    line.add_parcel(heavy(2, divert=False, scan_position_x=-4.0))
    assert line.command(stroke(1)).accepted
    snaps = []
    out = outcomes(run(line, 2.2, on_step=lambda ln: snaps.append(ln.snapshot())))
    assert out[1].code is OutcomeCode.SOLVER_FAILURE
    assert "min_dt" in out[1].reason
    after = [s for s in snaps if s.t >= out[1].t]
    assert after and all(p.parcel_id != 1 for s in after for p in s.parcels)
    for s in snaps:
        for p in s.parcels:
            assert np.isfinite([p.x, p.y, p.yaw, p.vx, p.vy]).all()
            assert abs(p.y) < 1.0 and p.deformation < 0.01
    # the fence follows the rigid drive for the rest of its cycle, then rests
    mid = next(s for s in after if s.t > 1.6)
    assert mid.fence.stroke_parcel_id == 1 and not mid.fence.from_solve
    assert mid.fence.drive_angle > 0.0
    assert snaps[-1].fence.stroke_parcel_id is None
    assert line.parcels_on_line == 1  # the bystander rides on


def test_bystander_in_the_swept_sector_is_warned_once():
    line = make_line()
    line.add_parcel(heavy(1))
    # a small parcel 0.45 m behind, at the fence side: it enters the sector during the stroke
    line.add_parcel(
        ParcelSpec(
            2,
            length_a=0.2,
            width_b=0.2,
            height=0.2,
            mass=2.0,
            lateral_gap=0.0,
            scan_position_x=-1.45,
        )
    )
    assert line.command(stroke(1)).accepted
    events = run(line, 3.0)
    warns = [e for e in events if isinstance(e, OverlapWarning)]
    assert len(warns) == 1 and (warns[0].stroke_parcel_id, warns[0].other_parcel_id) == (1, 2)
    assert 1.42 <= warns[0].t <= 1.42 + 0.7


def test_swept_sector_geometry():
    sq = [(0.5, 0.1), (0.7, 0.1), (0.7, 0.3), (0.5, 0.3)]  # inside the 40 deg sector
    assert in_swept_sector(sq, 1.2, ALPHA_K)
    far = [(2.0, 0.1), (2.2, 0.1), (2.2, 0.3), (2.0, 0.3)]
    assert not in_swept_sector(far, 1.2, ALPHA_K)
    upstream = [(-0.5, 0.0), (-0.1, 0.0), (-0.1, 0.3), (-0.5, 0.3)]
    assert not in_swept_sector(upstream, 1.2, ALPHA_K)
    # a big parcel containing the whole sector
    big = [(-0.1, -0.01), (1.3, -0.01), (1.3, 1.0), (-0.1, 1.0)]
    assert in_swept_sector(big, 1.2, ALPHA_K)


def test_every_parcel_gets_exactly_one_outcome():
    line = make_line()
    specs = [heavy(i, scan_position_x=-1.0 - 1.0 * i, divert=i % 2 == 0) for i in range(6)]
    for s in specs:
        line.add_parcel(s)
    for s in specs:
        if s.divert:
            assert line.command(stroke(s.parcel_id)).accepted
    out = outcomes(run(line, 12.0, dt=0.004))
    assert sorted(out) == list(range(6))
    for i, o in out.items():
        assert o.code is (OutcomeCode.SORTED if i % 2 == 0 else OutcomeCode.NOT_DIVERTED)
    assert line.parcels_on_line == 0


@pytest.mark.parametrize("method", ["scipy:LSODA", "cyrk:LSODA"])
def test_the_line_steps_a_baseline_and_a_compiled_peer_as_simulate_does(method):
    """One stepper interface: the line steps a SciPy baseline and a CyRK peer through the same
    SolveStepper as our schemes, and its outcome equals simulate()'s figures of that scheme."""
    sc = replace(SCENE, solver=replace(SCENE.solver, method=method, rtol=1e-4))
    line = SortingLine(LineConfig.from_scenario(sc))
    line.add_parcel(heavy(1))
    assert line.command(stroke(1)).accepted
    scenario = []

    def watch(ln: SortingLine) -> None:
        got = ln.stroke_scenario(1)
        if got is not None and not scenario:
            scenario.append(got)

    out = outcomes(run(line, 3.0, on_step=watch))[1]
    assert out.code is OutcomeCode.SORTED
    assert scenario[0].solver.method == method
    ref = simulate(replace(scenario[0], solver=replace(scenario[0].solver, stop_when_sorted=True)))
    assert ref.sorted
    assert out.peak_normal_force == ref.peak_contact_force
    assert out.exit_speed_y == ref.exit_speed_y
    # the same physics as our default scheme: the 0.3 m free fall's impact speed
    assert out.impact_normal_speed == pytest.approx(2.43, abs=0.03)


def test_line_config_is_checked():
    with pytest.raises(ValueError, match="solver.method"):
        SortingLine(
            LineConfig.from_scenario(replace(SCENE, solver=replace(SCENE.solver, method="rk99")))
        )
    with pytest.raises(ValueError, match="line_end_x"):
        SortingLine(LineConfig.from_scenario(SCENE, line_end_x=1.0))


def test_unsorted_stroke_is_missed_and_the_parcel_rides_on():
    line = make_line()
    line.add_parcel(heavy(5))
    # a 25 deg stroke hits the load but cannot push its C_s 0.3 m further across the belt
    assert line.command(stroke(5, alpha_k=math.radians(25.0))).accepted
    stages = []
    out = outcomes(
        run(
            line,
            6.0,
            on_step=lambda ln: stages.extend(p.stage for p in ln.snapshot().parcels),
        )
    )
    assert out[5].code is OutcomeCode.MISSED and not out[5].sorted
    assert "y_max" in out[5].reason and out[5].y_max < 0.7
    # the solve ran the fence cycle plus settle_time: 2 x 0.35 + 0.5 s after the start at 1.42 s
    assert out[5].t == pytest.approx(1.42 + 0.7 + 0.5, abs=DT)
    assert Stage.E1 in stages or Stage.E2 in stages  # the fence touched it
    assert stages[-1] is Stage.PASSED
    assert line.parcels_on_line == 0  # it left at the line end, with no second outcome


def test_stiff_fence_line_sorts_and_draws_a_straight_fence():
    sc = load_scene("positioned_stiff").scenario
    line = SortingLine(LineConfig.from_scenario(sc))
    spec = ParcelSpec(
        1,
        length_a=0.7,
        width_b=0.1,
        height=0.1,
        mass=5.0,
        cog_offset_x=-0.35,
        cog_offset_y=-0.05,
        divert=True,
        scan_position_x=-2.0,
    )
    line.add_parcel(spec)
    # the scene's drive (t1 0.9 s, R_s 0.7 m) at its belt speed 2 m/s
    assert line.command(StrokeCommand(1, r_s=0.7, t1=0.9, alpha_k=ALPHA_K)).accepted
    angles = []

    def watch(ln: SortingLine) -> None:
        f = ln.snapshot().fence
        angles.append(f.drive_angle)
        assert not f.deflection.any()
        np.testing.assert_allclose(np.hypot(f.node_x, f.node_y), f.node_s, atol=1e-12)

    out = outcomes(run(line, 4.0, on_step=watch))
    ref = simulate(replace(sc, parcel=replace(sc.parcel, lateral_gap=0.0)))
    assert out[1].code is OutcomeCode.SORTED and ref.sorted
    assert out[1].peak_normal_force == pytest.approx(ref.peak_contact_force, rel=1e-9)
    assert max(angles) == pytest.approx(ALPHA_K, rel=1e-3)


def _stream_line() -> SortingLine:
    line = make_line()
    line.add_parcel(heavy(1))
    line.add_parcel(heavy(2, divert=False, scan_position_x=-2.0))
    line.add_parcel(heavy(3, scan_time=0.5, scan_position_x=-3.5))
    assert line.command(stroke(1)).accepted
    assert line.command(stroke(3, r_s=0.3, t1=0.3)).accepted
    return line


def _snap_key(s):
    """(ids and flags, numbers) of a snapshot."""
    ids = (
        s.fence.from_solve,
        s.fence.stroke_parcel_id,
        tuple((p.parcel_id, p.stage) for p in s.parcels),
    )
    nums = [s.t, s.fence.drive_angle, s.fence.tip_deflection, *s.fence.node_y]
    for p in s.parcels:
        nums += [p.x, p.y, p.yaw, p.vx, p.vy, p.contact_normal_force]
        nums += [p.contact_normal_force_stiff, p.deformation]
    return ids, np.array(nums)


@pytest.mark.slow
def test_prefetch_steps_ahead_without_changing_anything():
    """Soft real time steps the solves ahead of the line clock in spare wall time (prefetch):
    the running ones past the sort crossing, the planned ones before their stroke starts. The
    events, outcome figures and snapshots must be the very same as stepping each cycle's
    physics when it is due (the adaptive step sequence does not depend on when the generator
    is advanced, and SORTED is reported from the solve up to its crossing)."""
    runs = []
    for horizon in (0.0, 0.05):
        line = _stream_line()
        snaps, ahead, solved_before_start = [], [], set()

        def on_step(ln, horizon=horizon, snaps=snaps, ahead=ahead, solved=solved_before_start):
            snaps.append(_snap_key(ln.snapshot()))
            if horizon:
                ln.prefetch(horizon, math.inf)
                ahead.extend(s.stepper.t + s.t_start - ln.t for s in ln.strokes if s.alive)
                solved.update(
                    pid
                    for pid, p in ln.parcels.items()
                    if p.prepared is not None and p.prepared.finished and p.stroke is None
                )

        events = run(line, 7.0, on_step=on_step)
        runs.append((outcomes(events), snaps, ahead, solved_before_start))
    (o0, s0, _, _), (o1, s1, ahead, solved_before_start) = runs
    assert max(ahead) > 0.03  # the solves really ran ahead of the line clock
    # every stroke of the stream was solved to its end before it started
    assert solved_before_start == {1, 3}
    assert o0.keys() == o1.keys() == {1, 2, 3}
    assert o0[1].code is OutcomeCode.SORTED and o0[3].code is OutcomeCode.SORTED
    for pid in o0:
        assert o0[pid] == o1[pid]
    # the same points interpolated; the modal sums may differ in the last bit (BLAS paths
    # depend on array alignment)
    assert len(s0) == len(s1)
    for (ids0, x0), (ids1, x1) in zip(s0, s1, strict=True):
        assert ids0 == ids1
        np.testing.assert_allclose(x1, x0, rtol=1e-12, atol=1e-15)


def test_prefetch_respects_its_wall_deadline():
    line = _stream_line()
    run(line, 1.5)  # parcel 1's stroke (from t = 1.42 s) is running, not yet sorted
    (s,) = [s for s in line.strokes if s.alive]
    t_before = s.stepper.t
    line.prefetch(0.5, 0.0)  # no spare time at all: nothing is stepped
    assert s.stepper.t == t_before
    ticks = iter(range(10**6))
    line.prefetch(0.5, 3.0, clock=lambda: next(ticks))  # three steps' worth of clock checks
    assert t_before < s.stepper.t


def test_prefetched_diverging_solve_is_reported_at_its_time_with_no_state_past_it():
    line = diverging_line()
    line.add_parcel(heavy(1))
    assert line.command(stroke(1)).accepted
    snaps = []

    def on_step(ln):
        ln.prefetch(1.0, math.inf)  # far ahead: the failure is found before it is due
        snaps.append(ln.snapshot())

    out = outcomes(run(line, 2.2, on_step=on_step))
    assert out[1].code is OutcomeCode.SOLVER_FAILURE
    (stroke_start,) = [s.t for s in snaps if s.fence.stroke_parcel_id == 1][:1]
    t_fail = out[1].t
    assert t_fail > stroke_start  # reported when the line reaches it, not when it was found
    for s in snaps:
        for p in s.parcels:
            assert np.isfinite([p.x, p.y, p.yaw, p.vx, p.vy]).all()
            assert abs(p.y) < 1.0 and p.deformation < 0.01


def _same_snapshot(a, b) -> None:
    assert a.t == b.t and len(a.parcels) == len(b.parcels)
    for name in ("drive_angle", "tip_deflection", "stroke_parcel_id", "from_solve"):
        assert getattr(a.fence, name) == getattr(b.fence, name)
    for name in ("node_x", "node_y", "deflection", "rotation"):
        assert np.array_equal(getattr(a.fence, name), getattr(b.fence, name))
    assert repr(a.parcels) == repr(b.parcels)  # exact floats; NaN contact points too


def test_a_capture_renders_the_snapshot_of_its_time_after_the_line_moved_on():
    """The pacing loop captures in its cycle and renders in the slack, after prefetch may
    have stepped the solve ahead and the next cycle moved the line clock on."""
    line = make_line()
    line.add_parcel(heavy(1))
    line.add_parcel(heavy(2, scan_position_x=-3.0, divert=False))
    assert line.command(stroke(1)).accepted
    seen_stroke = False
    for k in range(1, 1000):
        line.advance(k * DT)
        snap, cap = line.snapshot(), line.capture()
        seen_stroke |= snap.fence.from_solve and bool(snap.parcels[0].contact_normal_force)
        line.prefetch(0.05, math.inf)  # the solve runs ahead of the line clock
        line.advance((k + 0.5) * DT)
        _same_snapshot(line.render(cap), snap)
    assert seen_stroke  # the check covered a stroke in contact, not just the belt


@pytest.mark.slow
def test_event_trace_holds_every_step_up_to_the_sorting_and_its_peaks():
    """The EventTrace sent with a SORTED outcome: the stroke's accepted steps from its start
    to the step where C_s crossed y0 = s, from which the outcome's peaks follow again."""
    from fence_sorter.analysis.events import refined_peak
    from fence_sorter.line import EventTrace

    line = make_line()
    line.add_parcel(heavy(1))
    assert line.command(stroke(1)).accepted
    events = run(line, 3.0)
    (out,) = [e for e in events if isinstance(e, Outcome)]
    (trace,) = [e for e in events if isinstance(e, EventTrace)]
    assert out.code is OutcomeCode.SORTED
    assert events.index(trace) == events.index(out) + 1 and trace.t == out.t
    t = trace.column("t")
    assert t[0] == 0.0 and np.all(np.diff(t) > 0.0) and len(t) > 50
    assert trace.start_time + t[-1] <= out.t + 1e-9
    y = trace.column("y")
    assert y[-1] >= SCENE.conveyor.width > y[-2]
    n = trace.column("normal_force")
    peak = refined_peak(t, n, trace.column("contact_set"))
    assert peak == pytest.approx(out.peak_normal_force, rel=1e-12)
    assert peak / trace.mass == pytest.approx(out.peak_normal_accel, rel=1e-12)
    assert trace.impacts[0, 1] == out.impact_normal_speed
    assert np.max(trace.impacts[:, 2]) == out.peak_normal_force_stiff
    assert np.all(trace.column("deformation")[n > 0.0] > 0.0)  # force only in contact
