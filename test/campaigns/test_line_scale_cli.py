"""``python -m benchmarks line-scale``: the lines it generates from four_units' pattern are
valid line files with the units where the pattern puts them; bad options exit 2 with one line
naming the option and its allowed range (nothing is run)."""

from __future__ import annotations

import pytest
import yaml

from benchmarks import cli as cli_main
from benchmarks.commands.line_scale import line_of
from fence_sorter.line.line_file import load_line


@pytest.mark.parametrize("n", [1, 2, 8])
def test_a_generated_line_has_n_units_5_m_apart_each_serving_two_destinations(
    tmp_path, n: int
) -> None:
    path = tmp_path / f"units_{n}.yaml"
    path.write_text(yaml.safe_dump(line_of(n), sort_keys=False))
    line = load_line(str(path))  # the line file's own checks: zones apart and on the belt
    four = load_line("four_units")
    assert [u.name for u in line.units] == [f"unit_{k + 1}" for k in range(n)]
    assert [u.position for u in line.units] == [3.0 + 5.0 * k for k in range(n)]
    assert [u.side for u in line.units] == [four.units[k % 4].side for k in range(n)]
    served = [d for u in line.units for d in u.destinations]
    assert sorted(served) == sorted(f"D{j + 1}" for j in range(2 * n))  # each once
    assert line.length == pytest.approx(line.units[-1].position + 6.0)


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [("--units", "0,2", "[1, 16]"), ("--units", "a", "unit counts"),
     ("--parcels", "0", "[1, 10000]"), ("--rtf", "-1", "[0, 100]")],
)  # fmt: skip
def test_bad_option_exits_2_naming_it(tmp_path, capsys, option, value, allowed) -> None:
    out = tmp_path / "x.md"
    assert cli_main.main(["line-scale", option, value, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0] and allowed in err[0]
    assert not out.exists()
