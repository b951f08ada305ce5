"""The load model options of ``fence-sorter optimize`` (mass, belt width s, the minimal
object's length), the search ranges of ``--fix`` and the spread of the restarts."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from fence_sorter.cli.main import main as cli_main
from fence_sorter.cli.optimize import summary
from fence_sorter.optimize.problem import MINIMAL_SIZE, OptimizeSpec
from fence_sorter.optimize.restarts import restart_spread, spread_lines
from fence_sorter.optimize.solve import evaluate_point
from fence_sorter.physics.params import ParameterError

ALPHA_40 = math.radians(40.0)
#: a stroke that brings the positioned 0.7 x 0.1 m load to y_k ~ 0.69 m (C_s rear, Fig. 2a)
X = {"R_s": 0.7, "v": 2.0, "t1": 0.5, "R_z": 1.2}


def test_defaults_are_the_paper_load_on_the_paper_belt():
    spec = OptimizeSpec(case="arbitrary", alpha_k=ALPHA_40)
    assert (spec.mass, spec.belt_width, spec.min_length) == (5.0, 0.7, 0.1)
    loads = dict(spec.loads())
    assert loads["minimal_rear"].lateral_gap == pytest.approx(0.6)  # section 4.1: Delta_s


def test_mass_belt_width_and_min_length_shape_the_loads():
    spec = OptimizeSpec(
        case="arbitrary", alpha_k=ALPHA_40, mass=12.0, belt_width=1.2, min_length=0.3
    ).validate()
    loads = dict(spec.loads())
    assert {n: p.mass for n, p in loads.items()} == {
        "limiting_rear": 12.0,
        "limiting_front": 12.0,
        "minimal_rear": 1.0,
        "minimal_front": 1.0,
    }
    for cog in ("rear", "front"):
        minimal = loads[f"minimal_{cog}"]
        # on the far border: Delta_s + B = s
        assert minimal.lateral_gap + minimal.width_b == pytest.approx(1.2)
        assert (minimal.length_a, minimal.width_b) == (0.3, MINIMAL_SIZE)
    assert spec.a_max() == 0.7  # A_max of (2): the longer of A and the minimal length


def test_belt_width_moves_the_push_off_margin_by_the_widening():
    """(8) is s - y_k: a load the stroke leaves on the belt reaches the same y_k on any wider
    belt, so the margin grows by exactly the widening."""
    spec = OptimizeSpec(case="positioned", alpha_k=ALPHA_40, constraints=(8,))
    narrow = evaluate_point(spec, X)
    wide = evaluate_point(replace(spec, belt_width=1.0), X)
    assert narrow["margins"][8] > 0.0  # the rear-C_s load stops short of s = 0.7 m
    assert wide["margins"][8] - narrow["margins"][8] == pytest.approx(0.3, abs=1e-6)
    assert wide["violated"] == [8]


def test_mass_reaches_the_twin_and_a_stiff_drive_keeps_a_n_nearly_the_same():
    spec = OptimizeSpec(case="positioned", alpha_k=ALPHA_40, constraints=(8, 11))
    light = evaluate_point(spec, X)
    heavy = evaluate_point(replace(spec, mass=50.0), X)
    a_light = light["margins"][11] + spec.a_ndop
    a_heavy = heavy["margins"][11] + spec.a_ndop
    assert a_light > 0.0 and a_heavy != a_light  # the load model carries the mass
    assert a_heavy == pytest.approx(a_light, rel=0.05)  # a_N = N / m_p, stiff drive


@pytest.mark.parametrize(
    ("field", "value", "named"),
    [
        ("mass", 0.0, "mass must be in [0.01, 500] kg"),
        ("belt_width", 0.1, "belt_width must be in [0.2, 5] m"),
        ("min_length", 0.8, "min_length must be in [0.05, 0.7] m"),
        ("fixed", (("v", 9.0),), r"fixed.v must be in [0.2, 2.5] m/s"),
        ("fixed", (("t1", 0.05),), r"fixed.t1 must be in [0.1, 1.5] s"),
    ],
)
def test_out_of_range_values_are_refused_naming_the_range(field, value, named):
    with pytest.raises(ParameterError) as exc:
        OptimizeSpec(case="arbitrary", alpha_k=ALPHA_40, **{field: value}).validate()
    assert named in str(exc.value)


def test_a_fixed_value_follows_its_bound_override():
    spec = OptimizeSpec(
        case="positioned", alpha_k=ALPHA_40, bounds=(("v", 0.2, 9.5),), fixed=(("v", 9.0),)
    )
    assert spec.validate().fixed_values() == {"v": 9.0}


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--fix", "v=9"], "--fix v must be in [0.2, 2.5] m/s"),
        (["--mass", "-1"], "--mass must be in [0.01, 500] kg"),
        (["--belt-width", "6"], "--belt-width must be in [0.2, 5] m"),
        (["--min-length", "0.01"], "--min-length must be in [0.05, 0.7] m"),
        (["--belt-width", "0.5", "--load-width", "0.6"], "--load-width must be in [0.05, 0.5]"),
    ],
)
def test_cli_refuses_out_of_range_values_in_one_line(args, line, capsys):
    assert cli_main(["optimize", "--case", "arbitrary", "--alpha-k", "40", *args]) == 2
    err = capsys.readouterr().err
    assert line in err and err.count("\n") == 1


def test_cli_help_says_case_and_alpha_k_are_required(capsys):
    with pytest.raises(SystemExit):
        cli_main(["optimize", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--case {arbitrary,positioned} required" in text
    assert "--alpha-k DEG required" in text


def test_cli_prints_the_load_model_it_used(capsys):
    """(7) rules the box out in closed form: the answer comes without simulating."""
    argv = ["optimize", "--case", "arbitrary", "--alpha-k", "40"]
    argv += ["--mass", "8", "--belt-width", "1.1", "--min-length", "0.2"]
    argv += ["--bound", "R_s=-0.5:0", "--bound", "v=0.2:0.5", "--bound", "t1=0.1:0.3"]
    assert cli_main([*argv, "--json"]) == 0
    spec = json.loads(capsys.readouterr().out)["spec"]
    assert (spec["mass"], spec["belt_width"], spec["min_length"]) == (8.0, 1.1, 0.2)
    assert cli_main(argv) == 0
    out = capsys.readouterr().out
    assert "m_p = 8 kg, belt width s = 1.1 m" in out
    assert "minimal object 0.2 x 0.1 m, 1 kg at Delta_s = 1 m" in out


def test_restart_spread_of_three_disagreeing_restarts():
    optima = [6025.0, 2332.0, 6491.0]
    s = restart_spread(optima)
    assert (s["best"], s["median"], s["worst"]) == (6491.0, 6025.0, 2332.0)
    assert s["near_best"] == 1 and s["none_feasible"] == 0
    lines = spread_lines(s, optima)
    assert lines[0].startswith("restarts (3): 6025, 2332, 6491 pcs/h; best 6491, median 6025")
    assert "1 of 3 within 1% of the best" in lines[0]
    assert lines[1].startswith("warning: only one of 3 restarts reached the best")


def test_restart_spread_counts_restarts_within_one_percent_and_infeasible_ones():
    optima = [8000.0, 7930.0, 7900.0, math.nan]  # 7930 is within 1 % of 8000, 7900 is not
    s = restart_spread(optima)
    assert s["near_best"] == 2 and s["none_feasible"] == 1
    assert s["median"] == 7930.0 and s["worst"] == 7900.0
    lines = spread_lines(s, optima)
    assert len(lines) == 1 and "none feasible" in lines[0]


def test_summary_reports_every_restart_and_warns_on_a_lone_best():
    spec = OptimizeSpec(case="positioned", alpha_k=ALPHA_40).to_dict()
    optima = [2013.0, 1920.0, 1888.0]
    d = {
        "spec": spec,
        "feasible": True,
        "W_t": 2013.0,
        "Delta_c": 3.2,
        "X": {"R_s": 0.0, "v": 1.8, "t1": 0.9, "R_z": 2.5},
        "active": [],
        "margins": {7: -0.8},
        "restarts": optima,
        "restart_spread": restart_spread(optima),
        "evaluations": 462,
        "wall_time": 2.1,
    }
    text = summary(d)
    assert "restarts (3): 2013, 1920, 1888 pcs/h; best 2013, median 1920, worst 1888" in text
    assert "warning: only one of 3 restarts" in text
