"""The capacity optimiser (ROS-free): optimum on reduced problems, (1)-(2), the paper's trends,
infeasible problems, bad input, and the Dask path against the process pool."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import pytest

from fence_sorter.cli.main import main as cli_main
from fence_sorter.optimize import (
    OptimizeSpec,
    evaluate_point,
    evaluation_pool,
    grid_search,
    optimize,
)
from fence_sorter.optimize.problem import PAPER_RANGES
from fence_sorter.optimize.solve import closed_form
from fence_sorter.physics.params import ParameterError

ALPHA_40 = math.radians(40.0)
#: reduced problem: positioned load, (7), (8), (11); v and R_z held, R_s and t1 free
REDUCED = OptimizeSpec(
    case="positioned",
    alpha_k=ALPHA_40,
    constraints=(7, 8, 11),
    fixed=(("v", 2.0), ("R_z", 1.2)),
    budget=300,
)


@pytest.fixture(scope="module")
def pool():
    with evaluation_pool(workers=2) as ex:
        yield ex


@pytest.fixture(scope="module")
def reduced(pool):
    return optimize(REDUCED, pool)


@pytest.mark.slow
def test_reduced_optimum_is_feasible_within_ranges_and_re_evaluates(reduced):
    assert reduced.feasible and reduced.infeasible is None
    assert reduced.X["v"] == 2.0 and reduced.X["R_z"] == 1.2
    for name in ("R_s", "t1"):
        lo, hi = PAPER_RANGES[name]
        assert lo <= reduced.X[name] <= hi
    again = evaluate_point(REDUCED, reduced.X)  # a fresh twin evaluation of the answer
    assert again["feasible"]
    for c in REDUCED.constraints:
        assert again["margins"][c] <= 0.0, c
        assert again["margins"][c] == pytest.approx(reduced.margins[c], abs=1e-9)
    # the answer sits on the boundary: some constraint stops W_t from growing
    assert reduced.active and set(reduced.active) <= set(REDUCED.constraints)
    # the budget of each restart, plus the blocking probes
    assert reduced.evaluations <= REDUCED.budget * REDUCED.restarts + 4


def test_reduced_optimum_beats_a_coarse_grid(reduced, pool):
    coarse = grid_search(REDUCED, {"R_s": 0.25, "t1": 0.1}, pool)
    assert coarse["best"] is not None
    assert reduced.W_t >= coarse["best"]["W_t"]


def test_grid_search_is_exact_on_its_grid():
    """Visiting in W_t order and stopping at the first feasible batch finds the same point as
    evaluating the whole (small) grid."""
    spec = OptimizeSpec(
        case="positioned",
        alpha_k=ALPHA_40,
        constraints=(7, 8, 11),
        fixed=(("v", 2.0), ("R_z", 1.2), ("R_s", 0.8)),
    )
    g = grid_search(spec, {"t1": 0.1}, batch=1)
    every = [
        evaluate_point(spec, {"R_s": 0.8, "v": 2.0, "t1": 0.1 * k, "R_z": 1.2})
        for k in range(1, 16)
    ]
    feas = [r["W_t"] for r in every if r["feasible"]]
    assert feas and g["best"]["W_t"] == pytest.approx(max(feas), rel=1e-12)
    assert g["evaluations"] < len(every)  # it stopped early


def test_capacity_and_pitch_follow_1_and_2_exactly(reduced):
    x = reduced.X
    t_z = 2.0 * x["t1"] + abs(x["R_s"]) / x["v"]  # t_c = t1 + t2, t2 = t1
    assert reduced.Delta_c == pytest.approx(max(x["v"] * t_z, 0.7), rel=1e-12)
    assert reduced.W_t == pytest.approx(3600.0 * x["v"] / reduced.Delta_c, rel=1e-12)
    # the other branch of (2): v t_z below A_max + Delta gives Delta_c = A_max + Delta
    spec = OptimizeSpec(case="positioned", alpha_k=ALPHA_40, gap=0.2, constraints=(8,))
    r = evaluate_point(spec, {"R_s": 0.0, "v": 0.5, "t1": 0.3, "R_z": 1.2})
    assert r["Delta_c"] == pytest.approx(0.9, rel=1e-12)
    assert r["W_t"] == pytest.approx(3600.0 * 0.5 / 0.9, rel=1e-12)
    # (7) is closed-form: a point violating it is not simulated
    r7 = evaluate_point(REDUCED, {"R_s": 0.0, "v": 2.0, "t1": 0.2, "R_z": 1.2})
    assert not r7["simulated"] and r7["violated"] == [7]
    assert r7["margins"][7] == pytest.approx(0.7 / 2.0 - 0.2, rel=1e-12)


@pytest.mark.slow
def test_longer_load_gives_lower_capacity(reduced, pool):
    short = optimize(replace(REDUCED, load_length=0.3), pool)
    assert short.feasible
    assert short.W_t > 1.1 * reduced.W_t


@pytest.mark.slow
def test_constraint_12_lowers_capacity(reduced, pool):
    with12 = optimize(replace(REDUCED, constraints=(7, 8, 11, 12)), pool)
    assert with12.feasible
    assert with12.margins[12] <= 0.0
    assert with12.W_t < 0.9 * reduced.W_t


@pytest.mark.slow
def test_lower_friction_gives_higher_capacity(pool):
    """Fig. 4's set-up: arbitrary placement, R_s = 0, R_z = 1.4 m, alpha_k = 40 deg, (7)-(10)."""
    base = dict(
        case="arbitrary",
        alpha_k=ALPHA_40,
        constraints=(7, 8, 9, 10),
        fixed=(("R_s", 0.0), ("R_z", 1.4)),
        budget=300,
    )
    high = optimize(OptimizeSpec(**base, mu1=0.65, mu2=0.35), pool)
    low = optimize(OptimizeSpec(**base, mu1=0.3, mu2=0.15), pool)
    assert high.feasible and low.feasible
    assert low.W_t > 1.05 * high.W_t


def test_impossible_constraint_gives_the_infeasible_result(pool):
    r = optimize(replace(REDUCED, a_ndop=0.5, budget=100), pool)
    assert not r.feasible and r.X == {} and math.isnan(r.W_t)
    assert r.infeasible.startswith("infeasible:") and "(11)" in r.infeasible
    d = r.to_dict()
    assert d["feasible"] is False and d["W_t"] is None


def test_impossible_ranges_give_the_infeasible_result_without_simulating():
    # (7): (A - R_s)/v <= t1 cannot hold for A = 0.7 m with R_s <= 0, v <= 0.5, t1 <= 0.3
    spec = OptimizeSpec(
        case="positioned",
        alpha_k=ALPHA_40,
        constraints=(7, 8, 11),
        bounds=(("R_s", -0.5, 0.0), ("v", 0.2, 0.5), ("t1", 0.1, 0.3)),
    )
    r = optimize(spec)
    assert not r.feasible and r.evaluations == 0
    assert r.infeasible.startswith("infeasible: (7)")


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [
        ("case", "sideways", "case"),
        ("alpha_k", -0.1, "alpha_k"),
        ("mu1", 3.0, "mu1"),
        ("constraints", (7, 13), "constraints"),
        ("bounds", (("t1", 1.0, 0.5),), "bounds.t1"),
        ("fixed", (("speed", 1.0),), "speed"),
        ("budget", 0, "budget"),
        ("restarts", 0, "restarts"),
    ],
)
def test_spec_validation_names_the_field(field, value, named):
    kw = {"case": "positioned", "alpha_k": ALPHA_40, field: value}
    with pytest.raises(ParameterError, match=named):
        OptimizeSpec(**kw).validate()


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--alpha-k", "95"], "--alpha-k"),
        (["--alpha-k", "40", "--mu1", "-1"], "--mu1"),
        (["--alpha-k", "40", "--load-length", "9"], "--load-length"),
        (["--alpha-k", "40", "--constraints", "7,13"], "--constraints"),
        (["--alpha-k", "40", "--bound", "t1=1:0.5"], "--bound"),
        (["--alpha-k", "40", "--workers", "0"], "--workers"),
        (["--alpha-k", "40", "--restarts", "0"], "--restarts"),
        (["--alpha-k", "40", "--scheduler", "nowhere"], "scheduler"),
    ],
)
def test_cli_bad_arguments_exit_2_naming_the_option(args, named, capsys):
    assert cli_main(["optimize", "--case", "positioned", *args]) == 2
    err = capsys.readouterr().err
    assert named in err and "must" in err


def test_cli_infeasible_is_exit_0_with_json(capsys):
    import json

    argv = ["optimize", "--case", "positioned", "--alpha-k", "40", "--json"]
    argv += ["--bound", "R_s=-0.5:0", "--bound", "v=0.2:0.5", "--bound", "t1=0.1:0.3"]
    assert cli_main(argv) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["feasible"] is False and d["infeasible"].startswith("infeasible: (7)")


@pytest.mark.slow
def test_dask_cluster_gives_the_process_pool_optimum(reduced):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        with evaluation_pool(cluster.scheduler_address) as ex:
            on_dask = optimize(REDUCED, ex)
    assert on_dask.X == reduced.X
    assert on_dask.W_t == reduced.W_t
    assert on_dask.evaluations == reduced.evaluations


def test_a_looser_problem_started_from_the_tighter_optimum_is_not_lower(reduced, pool):
    """A looser (11) widens the feasible set: started from the tighter optimum, a search on a
    starved budget cannot return less."""
    loose = replace(REDUCED, a_ndop=2.0 * REDUCED.a_ndop, budget=30)
    r = optimize(loose, pool, starts=[reduced.X])
    assert r.feasible and r.W_t >= reduced.W_t


def test_a_start_on_the_bounds_is_accepted():
    """Sweep optima often sit on a bound (t1 = 0.1 s); SciPy rescales x0 to [0, 1], where
    t1 = 0.1 of the range [0.1, 1.5] lands at -1.1e-16 and was refused."""
    spec = replace(REDUCED, constraints=(7,), budget=8)  # (7) alone: decided in closed form
    start = {"R_s": 1.0, "v": 2.0, "t1": PAPER_RANGES["t1"][0], "R_z": 1.2}
    r = optimize(spec, None, starts=[start])
    assert r.feasible and r.W_t >= closed_form(spec, start)[0]


@pytest.mark.parametrize(
    ("start", "named"),
    [
        ({"R_s": 0.0, "v": 2.0, "t1": 0.5}, "lacks R_z"),
        ({"R_s": 0.0, "v": 1.0, "t1": 0.5, "R_z": 1.2}, "starts[0].v = 1 differs"),
        ({"R_s": 3.0, "v": 2.0, "t1": 0.5, "R_z": 1.2}, "starts[0].R_s = 3 m outside"),
    ],
)
def test_a_bad_start_is_refused_naming_it(start, named):
    with pytest.raises(ParameterError, match=re.escape(named)):
        optimize(REDUCED, None, starts=[start])


def test_restarts_are_independent_searches_and_the_best_counts(reduced):
    """Each restart's differential evolution runs with its own seed; the answer, after the
    compass search from the best of them, is at least the best any restart reached."""
    assert REDUCED.restarts == 3 and len(reduced.restarts) == 3
    # each restart spends its own budget (a callback SciPy took for the old style stopped
    # every restart after its first generation: ~200 evaluations in all)
    assert reduced.evaluations > 2 * REDUCED.budget
    reached = [w for w in reduced.restarts if math.isfinite(w)]
    assert reached and reduced.W_t >= max(reached) - 1e-9
    spread = reduced.to_dict()["restart_spread"]
    assert (spread["best"], spread["worst"]) == (max(reached), min(reached))
    assert spread["near_best"] == sum(w >= 0.99 * max(reached) for w in reached)
    assert evaluate_point(REDUCED, reduced.X)["W_t"] == pytest.approx(reduced.W_t, rel=1e-12)


def test_the_first_restart_is_the_single_search_and_more_restarts_never_lose(reduced, pool):
    """Restart 0 runs exactly as a one-restart search (same seed, same budget, its own compass
    search), so three restarts can only add to it."""
    single = optimize(replace(REDUCED, restarts=1), pool)
    assert reduced.restarts[0] == pytest.approx(single.W_t, rel=1e-12)
    assert reduced.W_t >= single.W_t
