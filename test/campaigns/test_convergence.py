"""The adaptive scheme converges with rtol: a user who tightens the tolerance gets a more
accurate peak force at a cost that grows smoothly (docs/design/numerics.md, "Convergence of the
adaptive scheme with rtol").

Each scene's default (``adaptive``) is solved at rtol 1e-4 ... 1e-7 (atol = 1e-2 rtol) and its
peak contact force compared with the committed reference (docs/reports/accuracy/reference/*.npz,
the trapezoidal scheme at dt = 3.9 us, converged to ~1e-9): the error at rtol 1e-7 is at least 100x
below the one at 1e-4 and never more than 2x above the one at the looser rtol before it, and the
steps grow with every decade of rtol by less than COST_GROWTH (4x). On a stiff fence that needs
the fence friction's stick resolved below the default rtol (``control.resolves_stick``): without
it arbitrary_stiff chatters between stick and slip from rtol 1e-6 (~1e5 steps a solve).
"""

from __future__ import annotations

import pytest

from benchmarks.convergence import (
    COST_GROWTH,
    GAIN,
    RTOLS,
    converges,
    smooth_cost,
    solve_at,
)


@pytest.mark.parametrize(
    "scene", ["impact_flexible", "slide_flexible", "positioned_stiff", "arbitrary_stiff"]
)
def test_peak_force_error_falls_100x_from_rtol_1e4_to_1e7_at_a_smoothly_growing_cost(
    scene,
) -> None:
    points = [solve_at(scene, rtol) for rtol in RTOLS]
    errors = [p.error for p in points]
    gain, monotone = converges(errors)
    assert gain, f"{scene}: errors {errors}: 1e-7 not {GAIN:g}x below 1e-4"
    assert monotone, f"{scene}: errors {errors} not monotone within 2x"
    steps = [p.steps for p in points]
    assert smooth_cost(steps), f"{scene}: steps {steps} not growing by < {COST_GROWTH:g}x a decade"


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--rtols", "5"], "solver.rtol must be in [1e-13, 0.1]"),
        (["--rtols"], "--rtols need at least one value"),
        (["--repeats", "0"], "--repeats must be >= 1"),
        (["--scenes", "nope"], "unknown scene 'nope'"),
    ],
)
def test_bad_options_exit_2_with_one_line_naming_them(args, names, capsys) -> None:
    from benchmarks.convergence import main

    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert names in err
