"""The inner solves of a trapezoidal step: the contact Newton iteration, the belt multiplier's
warm start and the slide-off location (kernel.trapezoidal_step, belt_multiplier, _locate)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fence_sorter.physics import kernel as K
from fence_sorter.physics.friction import _limits
from fence_sorter.physics.simulate import SortingModel
from fence_sorter.physics.stepper import Stepper
from fence_sorter.scene import load_scene

STIFF = load_scene("positioned_stiff").scenario


def _state_at(t: float):
    """positioned_stiff's model and solve advanced to the first accepted point >= t."""
    md = SortingModel(STIFF)
    cs = Stepper(md)
    cs.advance(t)
    return md, cs, int(cs.counters[0].cur)


def _evaluation(cs, i, out, res, lam):
    """The kernel.Evaluation of state row i (i None: of the given contacts, resultant, belt)."""
    if i is not None:
        out, res, lam = cs.contact_rows[i], cs.resultant_rows[i], cs.belt_wrench[i]
    modal = cs.modal_forces[i] if i is not None else np.zeros(0)
    return K.Evaluation(
        out, res, modal, cs.deflection, cs.deflection_rate, cs.nodes, cs.friction_prev, lam
    )


def _trapezoidal(step, md, cs, a, h, max_iter, force, tol):
    """One trapezoidal step of ``step`` (the compiled function or its Python body) from row a,
    with the given iteration tolerance and limit; (status, y1, end Evaluation)."""
    settings = cs.loop_model.settings.copy()
    settings[0].tol, settings[0].max_iter = tol, max_iter
    model = cs.loop_model._replace(settings=settings)
    y1 = np.zeros(md.n_state)
    end = _evaluation(cs, None, K.zero_slots(), K.zero_result(), np.zeros(3))
    props = (np.zeros((0, 2, 3)), np.zeros((0, 2)), np.zeros((0, 2)))
    status = step(
        model, props, h, 0.0, cs.times[a], cs.states[a], _evaluation(cs, a, None, None, None),
        np.zeros(0), 0.0, bool(cs.counters[0].on_belt), force, y1, end, cs.work,
    )  # fmt: skip
    return status, y1, end


def _step(md, cs, a, h, max_iter, force, tol=1e-14):
    """One trapezoidal step from row a (the Python body of the compiled function, so the module
    flag NEWTON is read at call time); (status, y1, iterations)."""
    status, y1, end = _trapezoidal(K.trapezoidal_step.py_func, md, cs, a, h, max_iter, force, tol)
    return status, y1, int(end.resultant[0]["iterations"])


def _distance(y, ref, h):
    """The iteration's own error measure: position plus h times velocity."""
    d = np.abs(y - ref)
    return float(d[:3].max() + h * d[3:6].max())


@pytest.mark.slow
@pytest.mark.parametrize("t", [0.1, 0.2, 0.4])
def test_newton_contact_iteration_converges_quadratically_to_the_plain_fixed_point(
    t, monkeypatch
) -> None:
    """Mid-push, sliding on the belt, the load pressed on the fence at two corners (t = 0.1,
    0.2 s) or at a corner and the fence tip in a face (0.4 s): Newton with the exact Jacobian
    (contacts' stiffness and damping, their geometry, the belt's slip map) and the
    Anderson-accelerated fixed point converge to the same end state (to round-off at a
    tolerance of 1e-14 m), Newton quadratically (e_2 <= 1e4 / m e_1^2, down to round-off),
    the fixed point linearly."""
    md, cs, a = _state_at(t)
    assert cs.resultant_rows[a, 0]["fence_n"] > 10.0  # pushing
    h = STIFF.solver.dt_max
    errors = {}
    ends = {}
    for newton in (True, False):
        monkeypatch.setattr(K.steps, "NEWTON", newton)
        status, ref, iterations = _step(md, cs, a, h, 50, False)
        assert status == K.STEP_OK and iterations < 10
        ends[newton] = ref
        errors[newton] = [_distance(_step(md, cs, a, h, k, True)[1], ref, h) for k in (1, 2)]
    assert _distance(ends[True], ends[False], h) < 1e-13
    e, plain = errors[True], errors[False]
    assert e[1] <= 1e4 * e[0] ** 2 + 1e-15, e
    assert e[0] < 0.2 * plain[0] and e[1] < 1e-3 * plain[1], (e, plain)


def test_newton_iteration_needs_fewer_force_evaluations_per_step(monkeypatch) -> None:
    """At the solver's tolerance (1e-9 m) a mid-push step converges in at most 2 evaluations
    with Newton (its second update is within round-off), 3-4 without it."""
    md, cs, a = _state_at(0.3)
    h = STIFF.solver.dt_max
    count = {}
    for newton in (True, False):
        monkeypatch.setattr(K.steps, "NEWTON", newton)
        status, _, count[newton] = _step(md, cs, a, h, 50, False, tol=STIFF.solver.tolerance)
        assert status == K.STEP_OK
    assert count[True] <= 2 < count[False], count


def _secular(u, w, f_max, t_max, sigma):
    p = np.array([f_max**2, f_max**2, t_max**2])
    c = np.asarray(w) * p
    return float(np.sum(p * np.asarray(u) ** 2 / (sigma + c) ** 2))


@pytest.mark.parametrize(
    "u",
    [(1.0, 0.5, 2.0), (-0.3, 1e-3, 0.0), (0.0, 0.0, 5.0), (2e-3, -1e-3, 1e-2)],
)
def test_belt_multiplier_from_any_start_is_the_same_root(u) -> None:
    """The slip multiplier sigma solves sum P_i u_i^2 / (sigma + W_i P_i)^2 = 1 wherever its
    Newton iteration starts: from 0 (the cold start), below or far above the root, or next to
    it (a contact iteration's previous iterate); the wrench is the same to round-off."""
    f_max, t_max = 10.0, 1.0
    w = (1e-4, 1e-4, 1e-3)
    p = _limits(f_max, t_max)
    lam0 = np.zeros(3)
    root = K.belt_multiplier(p, *u, *w, lam0, 0.0)
    assert root > 0.0  # slipping
    assert _secular(u, w, f_max, t_max, root) == pytest.approx(1.0, rel=1e-12)
    for start in (0.3 * root, root * (1 + 1e-9), 1.01 * root, 3.0 * root, 1e6 * root):
        lam = np.zeros(3)
        sigma = K.belt_multiplier(p, *u, *w, lam, start)
        assert sigma == pytest.approx(root, rel=1e-13), start
        np.testing.assert_allclose(lam, lam0, rtol=1e-12, atol=1e-12 * f_max)
    # a stuck belt ignores the start
    lam = np.zeros(3)
    assert K.belt_multiplier(p, 1e-4, 0.0, 0.0, *w, lam, 5.0) == -1.0
    assert lam[0] == pytest.approx(-1.0)  # -u/W


def test_a_slide_off_is_located_once_before_and_once_across(monkeypatch) -> None:
    """A corner sliding off the fence tip: one location ends the step just before it (within
    the iteration tolerance of the tip, so the force there is not skipped), the next ends just
    past it (within the tolerance); no further steps creep up on the tip (positioned_stiff
    slides one corner off). The end position jumps at a friction switch inside the trial
    step just past the tip; the secant on the smooth side before it reaches the tolerance in
    at most 5 trial steps (the Illinois secant across the jump took 10)."""
    loop = K.loop
    seen = []
    trials = []
    locate, step = loop._locate, loop._attempt

    def spy(*args):
        # the located trial is left in the trial row; its event function (slot, kind, g0, g1
        # are the last four arguments)
        trials.append(0)
        taken = locate.py_func(*args)  # as Python: its trial steps go through the spy below
        model, state = args[0], args[1]
        P, ctl, OUT = model.params, state.counters, state.contacts
        slot, kind, g0 = args[-4], args[-3], args[-2]
        if kind == K.EVENT_SLIDE_OFF:
            seen.append((g0, K.event_value(P, OUT[ctl[0].trial], slot, kind), trials[-1]))
        return taken

    def counted(*args):
        if trials:
            trials[-1] += 1
        return step(*args)

    # the loop's source run as Python (its callees compiled), with the spies in its module
    monkeypatch.setattr(loop, "_locate", spy)
    monkeypatch.setattr(loop, "_attempt", counted)
    stepper = Stepper(SortingModel(STIFF))
    model, state = stepper._loop_arrays()
    while loop.solve.py_func(model, state, 1 << 30, math.inf) != K.SOLVE_DONE:
        stepper._grow()
        model, state = stepper._loop_arrays()
    r = stepper.result()
    assert r.success
    assert len(seen) == 2, seen
    assert seen[0][2] <= 5, seen
    seen = [x[:2] for x in seen]
    (g0_before, g_before), (g0_across, g_across) = seen
    assert g0_before > STIFF.solver.tolerance
    assert 0.0 < g_before <= STIFF.solver.tolerance  # ends just before the tip
    assert g0_across == pytest.approx(g_before, abs=1e-15)
    assert -STIFF.solver.tolerance <= g_across < 0.0  # ends just past it
    assert math.isfinite(r.peak_contact_force)


def _free_step(gap):
    """positioned_stiff at t = 0 with the load moved ``gap`` off the fence, riding at the belt's
    speed: one compiled step of dt_max; its (y1, out, res) and an evaluation at its end."""
    md, cs, a = _state_at(0.0)
    cs.states[a, 1] += gap  # the long face along the fence (D = 0 at t = 0), moved off it
    h = STIFF.solver.dt_max
    status, y1, end = _trapezoidal(
        K.trapezoidal_step, md, cs, a, h, 50, False, STIFF.solver.tolerance
    )
    out, res = end.contacts, end.resultant
    assert status == K.STEP_OK and res[0]["iterations"] == 1
    out2, res2 = K.zero_slots(), K.zero_result()
    prev = np.full(K.N_SLOTS, math.nan)
    ev = K.Evaluation(
        out2, res2, np.zeros(0), cs.deflection, cs.deflection_rate, cs.nodes, prev, np.zeros(3)
    )
    K.evaluate(cs.loop_model, cs.times[a] + h, 0.0, y1, cs.belt_wrench[a], 0.5 * h, ev)
    return out, res, out2, res2


@pytest.mark.parametrize("near", [False, True])
def test_a_contact_free_step_ends_on_the_forces_at_its_end_state(near) -> None:
    """The load off the fence, riding at the belt's speed: the step converges in one
    evaluation. Its end forces (no contact: the state does not enter) equal an evaluation at
    the end state; its corners' D, the onset event's values, are within the tolerance of it
    when the load ends far off (5 cm: the step keeps its one evaluation) and exact when a
    corner ends within 10 tolerances of the fence (5e-9 m: the end state is evaluated again)."""
    tol = STIFF.solver.tolerance
    gap = 0.05
    if near:  # the gap that leaves the nearest corner 5e-9 m off the fence at the step end
        out2 = _free_step(gap)[2]
        gap += out2["d"][:4][out2["gap"][:4] != 0.0].max() + 5e-9
    out, res, out2, res2 = _free_step(gap)
    assert res2[0]["active_mask"] == 0.0
    fields = ["fx", "fy", "mz", "fence_n", "active_mask"]
    assert all(np.array_equal(res[f], res2[f]) for f in fields)
    d, d2 = out["d"][:4], out2["d"][:4]
    assert np.array_equal(out["gap"][:4], out2["gap"][:4])
    end_gap = -d2[out2["gap"][:4] != 0.0].max()
    if near:
        assert 0.0 < end_gap < 10 * tol
        assert np.array_equal(d, d2)
    else:
        assert end_gap > 0.04
        assert np.max(np.abs(d - d2)) <= 3 * tol
