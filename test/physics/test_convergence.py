"""The adaptive scheme converges with rtol: a user who tightens the tolerance gets a more
accurate peak force (docs/numerics.md, "Convergence of the adaptive scheme with rtol").

Each scene's default (``adaptive``) is solved at rtol 1e-4 ... 1e-7 (atol = 1e-2 rtol) and its
peak contact force compared with the committed reference (docs/accuracy/reference/*.npz, the
trapezoidal scheme at dt = 3.9 us, converged to ~1e-9): on a flexible fence the error at rtol
1e-7 is at least 100x below the one at 1e-4 and never more than 2x above the one at the looser
rtol before it. positioned_stiff converges monotonically at the rate of a second-order scheme
whose local error is held at rtol (rtol^(2/3), ~20x over the range); arbitrary_stiff is left
out (a friction stick/slip chatter from rtol 1e-6 costs ~1e5 steps a solve).
"""

from __future__ import annotations

import pytest

from fence_sorter.verification.convergence import GAIN, RTOLS, converges, solve_at


@pytest.mark.parametrize("scene", ["impact_flexible", "slide_flexible"])
def test_peak_force_error_falls_100x_from_rtol_1e4_to_1e7_on_a_flexible_fence(scene) -> None:
    points = [solve_at(scene, rtol) for rtol in RTOLS]
    errors = [p.error for p in points]
    gain, monotone = converges(errors)
    assert gain, f"{scene}: errors {errors}: 1e-7 not {GAIN:g}x below 1e-4"
    assert monotone, f"{scene}: errors {errors} not monotone within 2x"
    # the cost grows with the accuracy, by less than 10x a decade
    steps = [p.steps for p in points]
    assert all(a < b < 10 * a for a, b in zip(steps, steps[1:], strict=False)), steps


def test_positioned_stiff_converges_monotonically_at_the_second_order_rate() -> None:
    points = [solve_at("positioned_stiff", rtol) for rtol in RTOLS]
    errors = [p.error for p in points]
    _, monotone = converges(errors)
    assert monotone, f"errors {errors} not monotone within 2x"
    # rtol^(2/3) over three decades is 100x; the peak's steps at rtol 1e-4 are bounded by dt_max
    assert errors[-1] <= errors[0] / 15.0, errors
