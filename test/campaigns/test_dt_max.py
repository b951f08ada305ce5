"""``python -m benchmarks.dt_max``: a larger step cap takes fewer steps and, past 7 ms, a larger
peak-force error on positioned_stiff (docs/design/numerics.md, "dt_max on the stiff scenes");
bad arguments exit 2 in one line naming them."""

from __future__ import annotations

import pytest

from benchmarks.dt_max import main, measure


def test_fewer_steps_with_a_larger_cap_and_the_error_grows_past_7_ms() -> None:
    rows = measure("positioned_stiff", [5.0, 7.0, 10.0], 1)
    steps = [r["steps"] for r in rows]
    assert steps[0] > steps[1] > steps[2], steps
    errors = [r["error"] for r in rows]
    assert errors[2] > 2 * errors[1], errors  # 10 ms: the O(h^2) error of the longest steps
    assert all(1e-5 < e < 2e-3 for e in errors), errors


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--dt-max", "0"], "solver.dt_max must be in"),
        (["--rounds", "0"], "--rounds must be >= 1"),
        (["--scene", "nope"], "unknown scene 'nope'"),
        (["--from-json", "/nonexistent.json"], "--from-json"),
    ],
)
def test_bad_arguments_exit_2_with_one_line_naming_them(args, names, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main([*args, "--doc", "", "--json", ""])
    assert exc.value.code == 2
    assert names in capsys.readouterr().err.strip().splitlines()[-1]
