"""``python -m benchmarks line-bench``: one row per induction rate, written with its command;
bad options exit 2 with one line naming the option and its allowed range."""

from __future__ import annotations

import pytest

from benchmarks import cli as cli_main


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")]


def test_saturation_rows_conserve_parcels_and_keep_out_below_in(tmp_path, capsys) -> None:
    out = tmp_path / "line-bench.md"
    argv = ["line-bench", "two_units", "--parcels", "12", "--rates", "1500,6000", "--seed", "3"]
    assert cli_main.main([*argv, "--out", str(out)]) == 0
    text = out.read_text()
    assert text.startswith("# Line saturation curve (two_units)")
    assert "`python -m benchmarks line-bench two_units --parcels 12 --rates 1500,6000`" in text
    rows = [line for line in text.splitlines() if line.startswith("| ") and "---" not in line]
    assert len(rows) == 3  # the head and one row per rate
    for row, rate in zip(rows[1:], (1500, 6000), strict=True):
        cells = _cells(row)
        rate_set, rate_in, rate_out = (float(c) for c in cells[:3])
        assert rate_set == rate
        # the stream cannot be denser than asked; nothing leaves faster than it came in
        assert 0 < rate_in <= rate_set * 1.02 and 0 <= rate_out <= rate_in * 1.001
        assert cells[6] == "0" and cells[7] == "exact"  # no intrusion, every parcel counted
    assert capsys.readouterr().out.count("| exact |") == 2


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [("--rates", "0,2000", "[1, 100000]"), ("--rates", "a,b", "numbers"),
     ("--parcels", "0", "[1, 1000000]")],
)  # fmt: skip
def test_bad_option_exits_2_naming_it(tmp_path, capsys, option, value, allowed) -> None:
    out = tmp_path / "x.md"
    assert cli_main.main(["line-bench", option, value, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0] and allowed in err[0]
    assert not out.exists()
