"""``python -m benchmarks line-bench``: one row per induction rate, written with its command;
bad options exit 2 with one line naming the option and its allowed range."""

from __future__ import annotations

import pytest

from benchmarks import cli as cli_main


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")]


def test_saturation_rows_conserve_parcels_and_count_over_the_steady_window(
    tmp_path, capsys
) -> None:
    out = tmp_path / "line-bench.md"
    argv = ["line-bench", "two_units", "--duration", "60", "--rates", "1500,3000", "--seed", "3"]
    assert cli_main.main([*argv, "--out", str(out)]) == 0
    text = out.read_text()
    assert text.startswith("# Line saturation curve (two_units)")
    assert (
        "`python -m benchmarks line-bench two_units --duration 60 --rates 1500,3000 --seed 3`"
        in text
    )
    rows = [line for line in text.splitlines() if line.startswith("| ") and "---" not in line]
    assert len(rows) == 3  # the head and one row per rate
    unread = 0.05**2  # two_units: 5 % no-reads, 2 passes
    fill = 12.0 / 1.0 + 15.0  # its loop cycle: belt length / v + transit time
    for row, rate in zip(rows[1:], (1500, 3000), strict=True):
        cells = _cells(row)
        rate_set, rate_in, rate_out, ratio = (float(c) for c in cells[:4])
        assert rate_set == rate
        # the stream cannot be denser than asked (the window holds a few tens of parcels)
        assert 0 < rate_in <= rate_set * 1.5 and rate_out > 0
        assert ratio == pytest.approx(rate_out / (rate_in * (1 - unread)), abs=0.02)
        # the window's parcels sorted: a share of them, over the parcels some pass could read
        assert 0.0 < float(cells[4]) <= 1.0 / (1 - unread) + 1e-3
        start, end = (float(c) for c in cells[13].split("-"))
        assert start >= fill and end <= 60.0 + 60.0  # a loop cycle in; the held tail at most
        assert cells[8] == "0" and cells[9] == "exact"  # no intrusion, every parcel counted
        # every sorted parcel within (10)-(12) as delivered, no failed event
        assert cells[10] == "0 / 0 / 0" and cells[11] == "0"
    assert capsys.readouterr().out.count("| exact |") == 2


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [("--rates", "0,2000", "[1, 100000]"), ("--rates", "a,b", "numbers"),
     ("--parcels", "0", "[1, 1000000]"), ("--duration", "0", "[1, 100000]")],
)  # fmt: skip
def test_bad_option_exits_2_naming_it(tmp_path, capsys, option, value, allowed) -> None:
    out = tmp_path / "x.md"
    assert cli_main.main(["line-bench", option, value, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0] and allowed in err[0]
    assert not out.exists()
