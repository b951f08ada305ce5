"""``python -m benchmarks line-bench``: one row per induction rate, written with its command;
bad options exit 2 with one line naming the option and its allowed range."""

from __future__ import annotations

import json

import pytest

from benchmarks import cli as cli_main


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")]


def test_saturation_rows_conserve_parcels_and_count_the_window_s_cohort(tmp_path, capsys) -> None:
    out, js = tmp_path / "line-bench.md", tmp_path / "line-bench.json"
    argv = ["line-bench", "two_units", "--duration", "60", "--rates", "1500,3000", "--seed", "3"]
    assert cli_main.main([*argv, "--out", str(out), "--json", str(js)]) == 0
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
    doc = json.loads(js.read_text())
    assert [r["rate_set_pcs_h"] for r in doc["rows"]] == [1500, 3000]
    for row, rate, fig in zip(rows[1:], (1500, 3000), doc["rows"], strict=True):
        cells = _cells(row)
        rate_set, offered, rate_in, in_offered, rate_out, out_in, out_read = (
            float(c) for c in cells[:7]
        )
        assert rate_set == rate
        assert offered == pytest.approx(rate, rel=1e-3)  # a regular stream: as asked
        assert in_offered == pytest.approx(rate_in / offered, abs=2e-3)
        # the cohort: out / in is a share of it, out over in with the unread ones left out
        assert 0.0 < out_in <= 1.0 and rate_out <= rate_in
        assert out_in == pytest.approx(rate_out / rate_in, abs=2e-3)
        assert out_read == pytest.approx(out_in / (1 - unread), abs=2e-3)
        c = fig["steady"]["cohort"]
        assert c["inducted"] == c["sorted"] + c["rejected"] + c["failed"] + c["on_line"]
        assert fig["steady"]["out_over_in"] == c["sorted"] / c["inducted"]
        assert cells[7].startswith("yes (") == fig["steady"]["saturated"]
        assert fig["steady"]["saturated"] or cells[7] == "no"
        start, end = (float(c) for c in cells[16].split("-"))
        assert start >= fill and end <= 60.0 + 60.0  # a loop cycle in; the held tail at most
        assert cells[11] == "0" and cells[12] == "exact"  # no intrusion, every parcel counted
        # every sorted parcel within (10)-(12) as delivered, no failed event
        assert cells[13] == "0 / 0 / 0" and cells[14] == "0"
    assert capsys.readouterr().out.count("| exact |") == 2


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [("--rates", "0,2000", "[1, 100000]"), ("--rates", "a,b", "numbers"),
     ("--parcels", "0", "[1, 1000000]"), ("--duration", "0", "[1, 100000]"),
     ("--json", "/no/such/dir/x.json", "existing directory")],
)  # fmt: skip
def test_bad_option_exits_2_naming_it(tmp_path, capsys, option, value, allowed) -> None:
    out = tmp_path / "x.md"
    assert cli_main.main(["line-bench", option, value, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0] and allowed in err[0]
    assert not out.exists()
