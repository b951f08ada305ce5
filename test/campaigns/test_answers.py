"""``python -m benchmarks.answers``: a dump holds a solve's answers as ``simulate`` gives them,
two dumps of one tree compare equal, a change of one ulp in one array is named, and bad
arguments exit 2 with one line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks import answers
from fence_sorter.physics.scenario import RECORDABLE
from fence_sorter.physics.simulate import simulate
from fence_sorter.scene import load_scene


@pytest.mark.parametrize(
    "argv, message",
    [
        (["dump", "x.npz", "--scenes", "nowhere"], "unknown bench scene 'nowhere'"),
        (["dump", "x.npz", "--methods", "euler"], "unknown method 'euler'"),
        (["dump", "x.txt"], "FILE must be an .npz in an existing directory"),
        (["compare", "/no/such/a.npz", "/no/such/b.npz"], "/no/such/a.npz is not a file"),
    ],
)
def test_bad_arguments_exit_2_naming_them(argv, message, capsys) -> None:
    assert answers.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("answers: error: ") and message in err[0]


def test_dumps_hold_the_answers_and_compare_bitwise(tmp_path, capsys) -> None:
    a, b, c = (tmp_path / f"{n}.npz" for n in "abc")
    argv = ["--scenes", "positioned_stiff", "--methods", "trapezoidal"]
    assert answers.main(["dump", str(a), *argv]) == 0
    assert answers.main(["dump", str(b), *argv]) == 0
    with np.load(a) as data:
        saved = {k: data[k] for k in data.files}
    # the scene's own settings and the one method, each with both recordings
    prefixes = {k.rsplit("|", 1)[0] for k in saved}
    assert prefixes == {
        f"positioned_stiff|{m}|{r}" for m in ("own", "trapezoidal") for r in ("default", "all")
    }
    sc = load_scene("positioned_stiff").scenario
    sc = dataclasses.replace(
        sc,
        solver=dataclasses.replace(sc.solver, method="trapezoidal"),
        record=RECORDABLE,
    )
    r = simulate(sc)
    key = "positioned_stiff|trapezoidal|all"
    assert saved[f"{key}|peak_contact_force"] == r.peak_contact_force
    assert saved[f"{key}|steps"] == r.steps
    for name, series in r.series.items():
        np.testing.assert_array_equal(saved[f"{key}|series.{name}"], series)
    capsys.readouterr()
    assert answers.main(["compare", str(a), str(b)]) == 0
    assert capsys.readouterr().out.startswith(f"{len(saved)} arrays compared, 0 differ")
    changed = dict(saved)
    name = f"{key}|series.x"
    changed[name] = saved[name].copy()
    changed[name][-1] = np.nextafter(changed[name][-1], np.inf)
    np.savez(c, **changed)
    assert answers.main(["compare", str(a), str(c)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out == [f"{len(saved)} arrays compared, 1 differ", f"  {name}"]
