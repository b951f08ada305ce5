"""The solve loop (``kernel.solve``) driven by ``stepper.Stepper``: what it records and
reduces (every series, a point per accepted step, the stages as ``codes.Stage``), the typed
diagnosis of each divergence, the wall-time limit, and that stepping in chunks, reusing the
arrays of an earlier solve or what was packed of the scenario for it changes nothing."""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
import pytest

from fence_sorter.codes import Stage
from fence_sorter.physics import kernel as K
from fence_sorter.physics import model as M
from fence_sorter.physics import stepper as ST
from fence_sorter.physics.scenario import PER_SCENARIO_SIZE, per_scenario
from fence_sorter.physics.simulate import SortingModel, simulate
from fence_sorter.physics.stepper import STAGE_NAMES, Diagnosis, Failure, Stepper
from fence_sorter.scene import SceneError, load_scene
from fence_sorter.verification import stability_cases as C

S_ALL = ("trajectory", "fence", "forces", "stages")
# a contact far too stiff for the fixed step: the iteration fails down to min_dt
TOO_STIFF = [
    "contact.k_p=1e16",
    "solver.method=trapezoidal",
    "solver.dt=5e-3",
    "solver.min_dt=1e-3",
    "solver.max_iterations=2",
]


def test_every_series_is_recorded_at_every_accepted_point() -> None:
    """One point per accepted step and the initial one, in every series; the result's peaks
    bound the recorded ones (the peak N may lie between points: the parabola), y_max is the
    largest recorded y and the stage series enters each stage when the stage list says."""
    sc = dc.replace(load_scene("slide_flexible").scenario, record=S_ALL)
    r = simulate(sc)
    s = r.series
    assert set(s) >= {"t", "t_fence", "t_forces", "t_stage", "stage", "tip_deflection"}
    assert len(s["t"]) == r.steps + 1
    for key in ("t_fence", "t_forces", "t_stage"):
        np.testing.assert_array_equal(s[key], s["t"])
    assert np.all(np.diff(s["t"]) > 0.0)
    n_max = s["normal_force"].max()
    assert n_max <= r.peak_contact_force <= 1.05 * n_max
    assert r.y_max == s["y"].max()
    assert r.peak_tip_deflection == np.abs(s["tip_deflection"]).max()
    entered = [0] + [k for k in range(1, len(s["stage"])) if s["stage"][k] != s["stage"][k - 1]]
    assert [(str(s["stage"][k]), float(s["t_stage"][k])) for k in entered] == r.stages
    assert [name for name, _ in r.stages] == ["on_belt", "E2", "E3", "E2", "sorted"]


def test_stage_codes_are_the_stage_enum_and_names_its_labels() -> None:
    """One representation of a stage: the loop's codes are ``codes.Stage`` values, the
    result's names (JSON, CSV, bags) their labels, unchanged strings."""
    codes = (
        K.STAGE_CODE_ON_BELT,
        K.STAGE_CODE_E1,
        K.STAGE_CODE_E2,
        K.STAGE_CODE_E3,
        K.STAGE_CODE_E4,
        K.STAGE_CODE_SORTED,
    )
    assert [Stage(c).name for c in codes] == ["ON_BELT", "E1", "E2", "E3", "E4", "SORTED"]
    assert STAGE_NAMES == ("on_belt", "E1", "E2", "E3", "E4", "sorted", "passed")
    assert [Stage(c).label for c in codes] == list(STAGE_NAMES[:6])


def test_runaway_speed_is_diagnosed_with_its_kind_and_value() -> None:
    sc = dc.replace(load_scene("arbitrary_stiff").scenario, external_wrench=(0.0, 1e7, 0.0))
    stepper = Stepper(SortingModel(sc))
    assert stepper.advance() is False and stepper.status == "failed"
    d = stepper.diagnosis
    assert d.kind is Failure.RUNAWAY_SPEED and d.t == stepper.t
    assert d.value == pytest.approx(math.hypot(stepper.y[3], stepper.y[4]), rel=1e-12)
    assert d.value > SortingModel(sc).speed_limit
    r = stepper.result()
    assert r.diagnosis == d.text and d.text.startswith(f"load speed {d.value:.4g} m/s exceeds")


def test_each_divergence_check_names_its_kind() -> None:
    """``kernel.diverged`` on a spoiled point, through ``Stepper.diverged``: each check gives
    its kind, time, value and one-line text."""
    model = SortingModel(load_scene("impact_flexible").scenario)
    cases = {
        Failure.NON_FINITE: (7, math.nan, None, "non-finite state at t = 0.250000 s"),
        Failure.DEEP_PENETRATION: (None, None, 2.0 * model.deep, "deep penetration D = "),
        Failure.RUNAWAY_SPEED: (4, 2.0 * model.speed_limit, None, "load speed "),
    }
    for kind, (k, v, depth, text) in cases.items():
        stepper = Stepper(model)
        stepper.start()
        y = model.initial_state()
        res = stepper.resultants.copy()
        if k is not None:
            y[k] = v
        if depth is not None:
            res[0]["max_d"] = depth
        stepper.observe(0.25, y, np.zeros(3), stepper.contacts.copy(), res, True)
        d = stepper.diverged()
        assert isinstance(d, Diagnosis) and d.kind is kind and d.t == 0.25
        assert d.text.startswith(text) and stepper.status == "failed"
        if kind is Failure.DEEP_PENETRATION:
            assert d.value == depth
    healthy = Stepper(model)
    healthy.start()
    assert healthy.diverged() is None and healthy.running


def test_a_step_below_min_dt_fails_the_solve() -> None:
    sc = load_scene("positioned_stiff", TOO_STIFF).scenario
    stepper = Stepper(SortingModel(sc))
    while stepper.step() is None and stepper.running:
        pass
    d = stepper.diagnosis
    assert d.kind is Failure.STEP_BELOW_MIN_DT and d.value == 1e-3 and d.t == stepper.t
    assert "fell below solver.min_dt=0.001 s" in d.text


def test_wall_time_limit_stops_the_loop() -> None:
    case = next(c for c in C.CASES if c.name == "wall_time_limit")
    sc = load_scene(case.scene, case.override_strings()).scenario
    r = simulate(sc)
    assert not r.success and r.diagnosis.startswith("wall-time limit 0.5 s reached at t = ")
    assert 0.0 < r.sim_time < 2.0 * sc.drive.t1 and r.steps > 0


def test_advancing_in_chunks_is_the_same_solve() -> None:
    """``Stepper.advance(t_target)`` (a run-until entry for soft-real-time stepping) stops at
    the first accepted point at or past each target and changes nothing."""
    sc = load_scene("impact_flexible").scenario
    whole = Stepper(SortingModel(sc))
    assert whole.advance() is False
    chunked = Stepper(SortingModel(sc))
    t = 0.0
    while True:
        t += 0.02
        if not chunked.advance(t):
            break
        assert chunked.t >= t - 1e-12
    a, b = chunked.result(wall=0.0), whole.result(wall=0.0)
    assert dc.replace(a, series={}) == dc.replace(b, series={})
    assert list(a.series) == list(b.series) and len(a.series["t"]) == a.steps + 1
    for key, va in a.series.items():
        np.testing.assert_array_equal(va, b.series[key], err_msg=key)
    np.testing.assert_array_equal(chunked.y, whole.y)


def test_a_reused_workspace_gives_the_same_solve() -> None:
    """A one-shot solve hands its arrays to the next solve of the same shape: a run after runs
    of other scenes (another load, a sorted and an unsorted event, a diagnosed divergence) is
    the run on fresh arrays, and an earlier result's series are not overwritten."""
    sc = load_scene("positioned_stiff").scenario
    first = simulate(sc)
    kept = {k: v.copy() for k, v in first.series.items()}
    others = [
        load_scene("arbitrary_stiff").scenario,
        load_scene("positioned_stiff", ["drive.alpha_k_deg=5"]).scenario,
        load_scene("positioned_stiff", TOO_STIFF).scenario,
    ]
    outcomes = [simulate(other) for other in others]
    assert [(r.sorted, r.success) for r in outcomes] == [
        (True, True),
        (False, True),
        (False, False),
    ]
    again = simulate(sc)
    for f in ("peak_contact_force", "exit_speed_y", "steps", "rejected_steps", "events"):
        assert getattr(again, f) == getattr(first, f), f
    assert again.stages == first.stages and again.impacts == first.impacts
    assert again.energy == first.energy
    for k, v in kept.items():
        np.testing.assert_array_equal(first.series[k], v, err_msg=k)
        np.testing.assert_array_equal(again.series[k], v, err_msg=k)


def test_the_named_rows_are_views_of_each_state_row_once() -> None:
    """``loop.loop_rows`` names every row of the loop state's per-row arrays once (the trial
    pair, located, before, alpha, previous), as views: after a value per Row is written
    through it, each row of each array holds its own Row's value."""
    s = Stepper(SortingModel(load_scene("impact_flexible").scenario))
    _, state = s._loop_arrays()
    rows = K.loop.loop_rows(state)
    named = [*rows.trial, rows.located, rows.before, rows.alpha, rows.previous]
    assert len(named) == K.N_ROWS == state.states.shape[0]
    fields = {
        "time": "times",
        "state": "states",
        "acceleration": "accelerations",
        "belt": "belt_wrench",
        "contacts": "contacts",
        "resultant": "resultants",
        "modal": "modal_forces",
    }
    assert set(fields) == set(K.Row._fields)
    for name in fields.values():
        getattr(state, name).view(np.uint8)[...] = 0
    for i, row in enumerate(named):
        for field in fields:
            view = getattr(row, field).view(np.uint8)
            assert view.size > 0, field
            view[...] = 1 + i
    for name in fields.values():
        whole = getattr(state, name)
        for i in range(K.N_ROWS):
            assert np.all(whole[i : i + 1].view(np.uint8) == 1 + i), (name, i)


def _fresh(sc) -> object:
    """``simulate(sc)`` with nothing cached per scenario (packed model, loop settings)."""
    M._packed.cache_clear()
    ST._loop_static.cache_clear()
    return simulate(sc)


def _assert_same(a, b) -> None:
    assert dc.replace(a, series={}, wall_time=0.0) == dc.replace(b, series={}, wall_time=0.0)
    assert list(a.series) == list(b.series)
    for key, va in a.series.items():
        np.testing.assert_array_equal(va, b.series[key], err_msg=key)


@pytest.mark.parametrize("scene", ["positioned_stiff", "impact_flexible"])
def test_a_scene_packed_once_solves_as_a_fresh_packing(scene: str) -> None:
    """What a model and the loop read of a scenario is packed once per Scenario object and
    reused by its later solves: each of them is bitwise the solve of a fresh packing; a changed
    scene (a new Scenario) is packed anew and solves as fresh; a model whose parameters a caller
    changed (its own copy of ``P``) solves with them and changes no other model of the scene."""
    sc = load_scene(scene).scenario
    fresh = _fresh(sc)
    for _ in range(2):
        _assert_same(simulate(sc), fresh)
    changed = load_scene(scene, ["drive.alpha_k_deg=45", "contact.k_p=3e9"]).scenario
    again = simulate(changed)
    assert again.sorted and again.peak_contact_force != fresh.peak_contact_force
    _assert_same(again, _fresh(changed))
    _assert_same(simulate(sc), fresh)
    changed_p = SortingModel(sc)  # a caller changes a parameter: in its own copy of P
    changed_p.P = changed_p.P.copy()
    changed_p.P[0].mu2 = 0.0
    assert simulate(sc, changed_p).peak_contact_force != fresh.peak_contact_force
    assert SortingModel(sc).P[0].mu2 == sc.contact.mu_fence
    _assert_same(simulate(sc), fresh)


def test_the_per_scenario_cache_keeps_each_scenario_it_answers_for() -> None:
    """Keyed on identity: scenarios built and dropped one after another (whose ids Python may
    reuse) each get their own answer, an equal but distinct Scenario its own entry, and the
    cache holds at most PER_SCENARIO_SIZE entries."""
    built = []

    @per_scenario
    def alpha(sc):
        built.append(sc.drive.alpha_k)  # not the scenario: it may be dropped
        return sc.drive.alpha_k

    base = load_scene("positioned_stiff").scenario
    for k in range(3 * PER_SCENARIO_SIZE):
        sc = dc.replace(base, drive=dc.replace(base.drive, alpha_k=0.1 + 1e-3 * k))
        assert alpha(sc) == sc.drive.alpha_k
        assert alpha(sc) == sc.drive.alpha_k
        assert len(alpha.cache) <= PER_SCENARIO_SIZE
        del sc
    assert len(built) == 3 * PER_SCENARIO_SIZE  # one build each, none answered for another
    twin = dc.replace(base)
    assert twin == base and twin is not base
    alpha(base), alpha(twin)
    assert len(built) == 3 * PER_SCENARIO_SIZE + 2


def test_a_scene_setting_an_engine_is_refused() -> None:
    """There is one solve loop and no ``solver.engine`` field: a scene that sets it gets the
    loader's one-line error naming the field."""
    with pytest.raises(SceneError, match=r"solver\.engine") as err:
        load_scene("impact_flexible", ["solver.engine=compiled"])
    assert "\n" not in str(err.value)


@pytest.mark.slow
@pytest.mark.parametrize("b_p", [0.0, 3.3e5, 3.3e6])
@pytest.mark.parametrize("mass", [0.1, 5.0, 60.0])
def test_impact_peak_stops_past_the_deepest_compression_with_the_same_peak(mass, b_p) -> None:
    """The observers' N_stiff (``stiff_impact_peak_force``) stops once the load moves back out
    and the force falls (law (16): dN/dt < 0 while D' < 0 and N > 0): the same peak, exactly,
    as integrating the whole impact to separation."""
    for speed in (1e-10, 1.5e-6, 0.1, 2.44, 20.0):
        for k_p in (1.72e9, 1.72e12):
            full = K.stiff_impact_peak(mass, speed, b_p, k_p, 4000)
            assert K.stiff_impact_peak_force(mass, speed, b_p, k_p, 4000) == full[0] > 0.0


def test_the_peak_between_points_is_the_parabola_vertex_and_no_extrapolation():
    """Law-shaped peak N = 900 - 4e7 (t - 0.3)^2 sampled at 0.299, 0.3005, 0.302 s: the vertex
    is the exact 900 N. Three points 1 ns and 1 ms apart on a force chattering by 1 N around
    886 N: the parabola's vertex would lie at 2.5e5 N; the peak stays within the samples'
    spread, 886 + 1 N."""

    def law(t):
        return 900.0 - 4e7 * (t - 0.3) ** 2

    t = (0.299, 0.3005, 0.302)
    assert K.parabola_peak(t[0], law(t[0]), t[1], law(t[1]), t[2], law(t[2])) == pytest.approx(
        900.0, rel=1e-12
    )
    peak = K.parabola_peak(0.0, 885.0, 1e-9, 886.0, 1e-3, 885.0)
    assert 886.0 <= peak <= 887.0
