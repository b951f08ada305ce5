"""Compiled peers (``solver.method = cyrk:*``): CyRK's C++ solvers on ``kernel.rhs``.

The peers integrate the model's ODE form (explicit Karnopp friction), as the SciPy baselines
do. Their answers are checked against solvers they share no code with: SciPy's LSODA at
rtol 1e-10 on the same ODE form, and our trapezoidal scheme on the model's own form (0.3 %
apart in peak contact force on positioned_stiff, docs/accuracy/README.md).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("CyRK")

from fence_sorter.physics.params import CYRK_METHODS, ParameterError, SolverParams  # noqa: E402
from fence_sorter.physics.peers import solver_name  # noqa: E402
from fence_sorter.physics.simulate import simulate  # noqa: E402
from fence_sorter.scene import load_scene  # noqa: E402


def scene(name: str, **solver):
    sc = load_scene(name).scenario
    return replace(sc, solver=replace(sc.solver, **solver))


def rel(a: float, b: float) -> float:
    return abs(a - b) / abs(b)


@pytest.fixture(scope="module")
def references():
    """Peak contact force of positioned_stiff: SciPy LSODA at rtol 1e-10 on the ODE form, and
    our trapezoidal scheme at dt = 1.5625e-5 s (the bench's reference)."""
    ode = simulate(scene("positioned_stiff", method="scipy:LSODA", rtol=1e-10, atol=1e-12))
    ours = simulate(
        scene(
            "positioned_stiff",
            method="trapezoidal",
            dt=1.5625e-5,
            tolerance=1e-12,
            max_iterations=30,
        )
    )
    assert ode.success and ours.success
    return ode, ours


@pytest.mark.parametrize("method", ["cyrk:LSODA", "cyrk:BDF", "cyrk:Tsit5"])
def test_peak_force_converges_to_the_references_as_rtol_tightens(references, method):
    """From rtol 1e-2 to 1e-8 and 1e-9 the peak force closes on SciPy's converged answer to
    the floor of the peak's observation (N sampled at accepted points and the parabola through
    the last three: a few 1e-6 at these steps; SciPy's own reference moves 4e-6 from rtol
    1e-10 to 1e-11)."""
    ode, ours = references
    errors = {}
    for rtol in (1e-2, 1e-8, 1e-9):
        r = simulate(scene("positioned_stiff", method=method, rtol=rtol, atol=rtol * 1e-2))
        assert r.success and r.sorted, r.diagnosis
        assert r.method == method and r.steps > 10
        errors[rtol] = rel(r.peak_contact_force, ode.peak_contact_force)
    assert errors[1e-2] > 1e-4, errors
    assert max(errors[1e-8], errors[1e-9]) < 2e-5, errors
    # within the gap between the two forms of the model (0.3 %) of our own reference
    assert rel(r.peak_contact_force, ours.peak_contact_force) < 1e-2
    assert r.exit_speed_y == pytest.approx(ode.exit_speed_y, rel=1e-6)
    assert r.y_max == pytest.approx(ode.y_max, abs=1e-9)  # both end on the belt edge


@pytest.mark.parametrize("method", CYRK_METHODS)
def test_every_peer_sorts_like_the_scipy_baseline(references, method):
    ode, _ = references
    r = simulate(scene("positioned_stiff", method=method, rtol=1e-6, atol=1e-8))
    assert r.success and r.sorted, r.diagnosis
    assert [s for s, _ in r.stages][-1] == "sorted"
    assert rel(r.peak_contact_force, ode.peak_contact_force) < 1e-3
    assert r.sim_time == pytest.approx(ode.sim_time, abs=1e-6)  # the belt-edge crossing
    assert r.energy_excess < 1e-3


def test_peer_points_go_through_the_loops_reductions():
    """One recorded point per accepted step and the initial one, the last on the belt edge
    (found from the accepted steps), the exit speed vy interpolated there."""
    sc = scene("positioned_stiff", method="cyrk:BDF", rtol=1e-5, atol=1e-7)
    sc = replace(sc, record=("trajectory", "forces", "stages"))
    r = simulate(sc)
    assert r.success and r.sorted, r.diagnosis
    s = r.series
    assert len(s["t"]) == r.steps + 1 and np.all(np.diff(s["t"]) > 0.0)
    width = sc.conveyor.width
    assert width <= s["y"][-1] < width + 1e-9 and np.all(s["y"][:-1] < width)
    n_max = s["normal_force"].max()
    assert n_max <= r.peak_contact_force <= 1.05 * n_max
    assert r.stages[0][0] == "on_belt" and r.stages[-1][0] == "sorted"


def test_after_sorting_the_peer_restarts_without_belt_friction():
    """impact_flexible runs on after the sort: the load's velocity stays constant once the
    fence has let go (the solve restarted at the crossing with the belt off)."""
    sc = scene("impact_flexible", method="cyrk:LSODA", rtol=1e-6, atol=1e-8)
    sc = replace(sc, record=("trajectory", "stages"))
    r = simulate(sc)
    assert r.success and r.sorted, r.diagnosis
    t_sorted = dict(r.stages)["sorted"]
    t_free = max(t for st, t in r.stages if st == "E4")
    s = r.series
    after = s["t"] > max(t_sorted, t_free) + 1e-3
    assert after.sum() > 5
    for key in ("vx", "vy", "phidot"):
        assert np.ptp(s[key][after]) < 1e-9, key


def test_a_bad_method_is_refused_naming_the_allowed_values():
    assert solver_name("cyrk:Tsit5") == "Tsit5"
    with pytest.raises(ValueError, match="one of cyrk:LSODA, cyrk:BDF, .*cyrk:Tsit5$"):
        solver_name("cyrk:Euler")
    with pytest.raises(ParameterError) as err:
        SolverParams(method="cyrk:Euler").validate()
    text = str(err.value)
    assert "\n" not in text and "solver.method" in text and "cyrk:LSODA" in text
