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

import json

import pytest

from benchmarks.convergence import (
    BEGIN,
    COST_GROWTH,
    END,
    GAIN,
    RTOLS,
    ConvergencePoint,
    converges,
    main,
    render,
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
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert names in err


def test_from_json_renders_the_section_again_without_measuring(tmp_path, capsys) -> None:
    """--from-json rewrites only the marked section of --doc, with the JSON's figures; a JSON
    that is not a convergence report, or a document without the marks, exits 2 naming it."""
    points = [
        ConvergencePoint("s", r, e, n, 0, 1e-3)
        for r, e, n in ((1e-4, 1e-3, 100), (1e-7, 1e-6, 900))
    ]
    data = {
        "command": "python -m benchmarks.convergence --rtols 1e-4 1e-7",
        "commit": "abc1234",
        "load_average": "0.10 0.20 0.30",
        "repeats": 1,
        "atol_per_rtol": 0.01,
        "rtols": [1e-4, 1e-7],
        "points": [p.__dict__ for p in points],
    }
    src = tmp_path / "c.json"
    src.write_text(json.dumps(data), encoding="utf-8")
    doc = tmp_path / "doc.md"
    doc.write_text(f"before\n\n{BEGIN}\nold\n{END}\n\nafter\n", encoding="utf-8")
    assert main(["--from-json", str(src), "--doc", str(doc), "--json", ""]) == 0
    text = doc.read_text(encoding="utf-8")
    assert text == f"before\n\n{render(data)}\n\nafter\n"
    assert "| s | 1.0e-03 / 100 / 1.00 | 1.0e-06 / 900 / 1.00 | 1000x |" in text
    capsys.readouterr()
    bad = tmp_path / "bad.json"
    bad.write_text("{}", encoding="utf-8")
    with pytest.raises(SystemExit) as exc:
        main(["--from-json", str(bad), "--doc", str(doc)])
    assert exc.value.code == 2
    assert "--from-json" in capsys.readouterr().err.strip().splitlines()[-1]
    plain = tmp_path / "plain.md"
    plain.write_text("no marks\n", encoding="utf-8")
    with pytest.raises(SystemExit) as exc:
        main(["--from-json", str(src), "--doc", str(plain)])
    assert exc.value.code == 2
    assert "--doc" in capsys.readouterr().err.strip().splitlines()[-1]
