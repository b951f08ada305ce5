"""The compiled solve loop (``solver.engine = compiled``, ``engine.py`` / ``kernel.solve``) is
the Python loop (``integrators.Integrator`` with ``simulate.Observer``) step for step: the same
steps, rejections, located events, peaks, impacts, stages, exit speed and recorded series on
every bench scene and every fast stability case, the same diagnoses with the same text, and the
same solve when it is advanced in chunks."""

from __future__ import annotations

import dataclasses as dc
import math
from pathlib import Path

import numpy as np
import pytest

from fence_sorter.physics import kernel as K
from fence_sorter.physics.engine import CompiledSolve, uses_compiled
from fence_sorter.physics.integrators import Integrator, State
from fence_sorter.physics.params import ParameterError, SolverParams
from fence_sorter.physics.simulate import Observer, SortingModel, simulate
from fence_sorter.scene import load_scene
from fence_sorter.verification import stability as S

SCENES = sorted(p.stem for p in Path("config/scenes").glob("*.yaml"))
# the wall-time case stops at a wall-clock time, so the two loops stop at different points
CASES = [c for c in S.fast_cases() if c.name != "wall_time_limit"]
ROUND_OFF = 1e-12
S_ALL = ("trajectory", "fence", "forces", "stages")


def _engine(sc, engine: str):
    return dc.replace(sc, solver=dc.replace(sc.solver, engine=engine))


def _close(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b or abs(a - b) <= ROUND_OFF * max(abs(a), abs(b), 1e-300)


def assert_same_solve(py, cc) -> None:
    """Every figure of two SimulationResults agrees to round-off (counts exactly)."""
    for name in ("success", "sorted", "reason", "diagnosis", "steps", "rejected_steps"):
        assert getattr(py, name) == getattr(cc, name), name
    assert (py.forced_steps, py.events, py.method) == (cc.forced_steps, cc.events, cc.method)
    for name in (
        "peak_contact_force",
        "peak_contact_force_stiff",
        "peak_normal_accel",
        "impact_normal_speed",
        "exit_speed_y",
        "y_max",
        "peak_tip_deflection",
        "sim_time",
        "energy_excess",
        "max_penetration",
    ):
        assert _close(getattr(py, name), getattr(cc, name)), (
            name,
            getattr(py, name),
            getattr(cc, name),
        )
    assert [s for s, _ in py.stages] == [s for s, _ in cc.stages]
    assert all(_close(a, b) for (_, a), (_, b) in zip(py.stages, cc.stages, strict=True))
    assert len(py.impacts) == len(cc.impacts)
    for ia, ib in zip(py.impacts, cc.impacts, strict=True):
        assert all(_close(a, b) for a, b in zip(ia, ib, strict=True)), (ia, ib)
    for f in dc.fields(py.energy):
        va, vb = getattr(py.energy, f.name), getattr(cc.energy, f.name)
        if isinstance(va, tuple):
            assert all(_close(a, b) for a, b in zip(va, vb, strict=True)), f.name
        else:
            assert _close(va, vb), (f.name, va, vb)
    assert list(py.series) == list(cc.series)
    for key, va in py.series.items():
        vb = cc.series[key]
        assert va.shape == vb.shape and va.dtype == vb.dtype, key
        if va.dtype.kind == "f":
            np.testing.assert_allclose(vb, va, rtol=ROUND_OFF, atol=1e-300, err_msg=key)
        else:
            np.testing.assert_array_equal(vb, va, err_msg=key)
    assert py.model_parts == cc.model_parts


def _both(sc):
    return simulate(_engine(sc, "python")), simulate(_engine(sc, "compiled"))


@pytest.mark.slow
@pytest.mark.parametrize("scene", SCENES)
def test_compiled_loop_is_the_python_loop_on_every_scene(scene: str) -> None:
    sc = load_scene(scene).scenario
    assert uses_compiled(sc)  # the default engine
    py, cc = _both(sc)
    assert py.steps > 50 and py.sorted  # the scenes are real sorting events
    assert_same_solve(py, cc)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_compiled_loop_is_the_python_loop_on_the_stability_cases(case: S.Case) -> None:
    sc = load_scene(case.scene, case.override_strings()).scenario
    py, cc = _both(sc)
    assert_same_solve(py, cc)
    if case.expected == "diagnosed":
        assert cc.diagnosis and case.cause in cc.diagnosis


def test_every_series_is_recorded_alike() -> None:
    sc = dc.replace(load_scene("slide_flexible").scenario, record=S_ALL)
    py, cc = _both(sc)
    assert set(cc.series) >= {"t", "t_fence", "t_forces", "t_stage", "stage", "tip_deflection"}
    assert len(cc.series["t"]) == cc.steps + 1  # the initial point and every accepted step
    assert_same_solve(py, cc)


def test_runaway_speed_is_diagnosed_alike() -> None:
    sc = dc.replace(load_scene("arbitrary_stiff").scenario, external_wrench=(0.0, 1e7, 0.0))
    py, cc = _both(sc)
    assert cc.diagnosis is not None and cc.diagnosis.startswith("load speed")
    assert_same_solve(py, cc)


def test_diagnosis_texts_are_the_python_loop_texts() -> None:
    """Each divergence the compiled loop finds reads as ``Integrator._diverged`` writes it."""
    model = SortingModel(load_scene("impact_flexible").scenario)
    integ = Integrator(model)
    solve = CompiledSolve(model)
    st = State(model.n_state, model.n_modes)
    st.t = 0.25
    st.y[:] = model.initial_state()
    cases = {
        K.DIAG_NONFINITE: lambda s: s.y.__setitem__(7, math.nan),
        K.DIAG_DEEP: lambda s: s.res.__setitem__(K.R_MAX_D, 2.0 * model.deep),
        K.DIAG_SPEED: lambda s: s.y.__setitem__(4, 2.0 * model.speed_limit),
    }
    for code, spoil in cases.items():
        s = State(model.n_state, model.n_modes)
        s.copy_from(st)
        spoil(s)
        found = K._diverged(model.P, solve.cfg, solve.fc, s.t, s.y, s.res)
        assert found == code
        solve.ctl[K.I_DIAG] = found
        assert solve._diagnosis() == integ._diverged(s)
    solve.ctl[K.I_DIAG] = K.DIAG_NONE
    assert solve._diagnosis() is None and integ._diverged(st) is None


def test_wall_time_limit_stops_the_compiled_loop() -> None:
    case = next(c for c in S.CASES if c.name == "wall_time_limit")
    sc = load_scene(case.scene, case.override_strings()).scenario
    r = simulate(_engine(sc, "compiled"))
    assert not r.success and r.diagnosis.startswith("wall-time limit 0.5 s reached at t = ")
    assert r.wall_time < sc.solver.max_wall_time + 0.5
    assert 0.0 < r.sim_time < 2.0 * sc.drive.t1 and r.steps > 0


def test_advancing_in_chunks_is_the_same_solve() -> None:
    """``CompiledSolve.advance(t_target)`` (a run-until entry for soft-real-time stepping)
    stops at the first accepted point at or past each target and changes nothing."""
    sc = load_scene("impact_flexible").scenario
    whole = CompiledSolve(SortingModel(sc))
    assert whole.advance() is False
    chunked = CompiledSolve(SortingModel(sc))
    t = 0.0
    while True:
        t += 0.02
        if not chunked.advance(t):
            break
        assert chunked.t >= t - 1e-12
    assert chunked.outcome() == whole.outcome()
    np.testing.assert_array_equal(chunked.Y[chunked.ctl[K.I_CUR]], whole.Y[whole.ctl[K.I_CUR]])


def test_a_reused_workspace_gives_the_same_solve() -> None:
    """run_compiled hands its arrays to the next solve of the same shape: a run after runs of
    other scenes (another load, a sorted and an unsorted event, a diagnosed divergence) is the
    run on fresh arrays, and an earlier result's series are not overwritten."""
    sc = load_scene("positioned_stiff").scenario
    first = simulate(sc)
    kept = {k: v.copy() for k, v in first.series.items()}
    others = [
        load_scene("arbitrary_stiff").scenario,
        load_scene("positioned_stiff", ["drive.alpha_k_deg=5"]).scenario,
        load_scene(
            "positioned_stiff",
            [
                "contact.k_p=1e16",
                "solver.method=trapezoidal",
                "solver.dt=5e-3",
                "solver.min_dt=1e-3",
                "solver.max_iterations=2",
            ],
        ).scenario,
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


@pytest.mark.parametrize("scene", ["impact_flexible", "positioned_stiff"])
def test_compiled_generalized_alpha_is_the_python_loop(scene: str) -> None:
    """generalized_alpha runs in the compiled loop: the same steps, located events, peaks and
    stages as the Python loop, with consistent accelerations at the start and at every restart
    after an event or a drive breakpoint."""
    sc = load_scene(scene, ["solver.method=generalized_alpha", "solver.dt=2e-4"]).scenario
    assert uses_compiled(sc)
    py, cc = _both(dc.replace(sc, record=S_ALL))
    assert py.success and py.sorted and py.events >= 2
    assert_same_solve(py, cc)


def test_scipy_keeps_its_own_loop() -> None:
    sc = load_scene("impact_flexible").scenario
    assert not uses_compiled(dc.replace(sc, solver=dc.replace(sc.solver, method="scipy:LSODA")))
    assert not uses_compiled(_engine(sc, "python"))


def test_bad_engine_is_refused_naming_the_field() -> None:
    with pytest.raises(ParameterError, match=r"solver\.engine must be one of compiled, python"):
        SolverParams(engine="numba").validate()
    with pytest.raises(ParameterError, match=r"solver\.engine .*'fortran'"):
        load_scene("impact_flexible", ["solver.engine=fortran"])


def _stepped(sc, engine: str, chunk: float):
    """Observer result of a solve stepped through Integrator.stepping/advance in chunks."""
    sc = _engine(sc, engine)
    model = SortingModel(sc)
    integ = Integrator(model)
    obs = Observer(model)
    seen: list[float] = []

    def observer(st, on_belt):
        seen.append(st.t)
        return obs(st, on_belt)

    stepper = integ.stepping(observer)
    t, yielded = 0.0, []
    while True:
        t += chunk
        alive = integ.advance(stepper, t)
        yielded.append(integ.cur.t)
        if not alive:
            break
        assert integ.cur.t >= t - 1e-12
    t_end, diagnosis, steps, rejected = integ.outcome
    r = obs.result(t_end, diagnosis, steps, rejected, 0.0, integ.forced, integ.events)
    return r, seen, yielded, integ.cur.y.copy()


@pytest.mark.parametrize(
    "scene, sets",
    [
        ("impact_flexible", []),
        ("positioned_stiff", []),
        ("impact_flexible", ["parcel.length_a=0.02"]),  # deep penetration: a diverged end
        ("slide_flexible", ["solver.method=trapezoidal"]),
    ],
)
def test_stepping_generator_replays_the_compiled_loop(scene: str, sets: list[str]) -> None:
    """Integrator.stepping on the compiled loop (the soft-real-time line steps it in chunks)
    hands the observer the same points as the Python loop and ends with the same outcome."""
    sc = load_scene(scene, sets).scenario
    assert Integrator(SortingModel(sc)).compiled
    py, seen_py, yielded_py, y_py = _stepped(sc, "python", 0.013)
    cc, seen_cc, yielded_cc, y_cc = _stepped(sc, "compiled", 0.013)
    assert seen_cc == seen_py and yielded_cc == yielded_py
    np.testing.assert_array_equal(y_cc, y_py)
    assert_same_solve(py, cc)
    assert_same_solve(simulate(sc), cc)  # and the same as the one-call compiled solve


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
