"""``fence-sorter run --line LINE --units ...``: which units a partial line starts here, and
the one-line refusals (exit 2) of a bad ``--units`` or an option that needs ``--line``."""

from __future__ import annotations

import pytest
from processes import run_cli

from fence_sorter.runner.line_job import BadLineInput, parse_units

NAMES = ["unit_1", "unit_2", "unit_3", "unit_4"]


@pytest.mark.parametrize(
    ("text", "indices"),
    [
        (None, (0, 1, 2, 3)),
        ("3,4", (2, 3)),
        ("4,3", (2, 3)),
        ("unit_2", (1,)),
        (" 1 , unit_4", (0, 3)),
    ],
)
def test_units_are_numbers_or_names_in_line_order(text: str | None, indices: tuple) -> None:
    assert parse_units(text, NAMES) == indices


@pytest.mark.parametrize(
    ("text", "why"),
    [("", "give units"), (" ", "give units"), ("1,,2", "give units"), ("0", "'0' is no unit"),
     ("5", "'5' is no unit"), ("unit_9", "'unit_9' is no unit"), ("x", "'x' is no unit"),
     ("2,unit_2", "given twice"), ("3,3", "given twice")],
)  # fmt: skip
def test_a_bad_units_list_names_the_option_and_the_allowed_values(text: str, why: str) -> None:
    with pytest.raises(BadLineInput) as exc:
        parse_units(text, NAMES)
    msg = str(exc.value)
    assert msg.startswith("--units: ") and why in msg, msg
    assert "1..4 or unit_1, unit_2, unit_3, unit_4" in msg and "\n" not in msg


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--line", "two_units", "--units", "3"], "--units"),
        (["--line", "two_units", "--units", "1,1"], "--units"),
        (["--line", "two_units", "--units", ""], "--units"),
        (["--line", "two_units", "--interface", "127.0.0.1"], "--interface"),
        (["--line", "two_units", "--interface", "10.255.1.1", "--peers", "10.0.0.2"],
         "--interface"),
        (["--units", "1"], "--units"),
        (["--no-owner"], "--no-owner"),
        (["--line", "two_units", "--view-period", "-1"], "--view-period"),
        (["--line", "two_units", "--view-period", "nan"], "--view-period"),
        (["--line", "two_units", "--live-rrd", "/tmp/x.txt"], "--live-rrd"),
        (["--line", "two_units", "--live-rrd", "/nonexistent_dir/x.rrd"], "--live-rrd"),
        (["--line", "two_units", "--units", "2", "--no-owner", "--rerun-url",
          "rerun+http://127.0.0.1:9876/proxy"], "--rerun-url"),
        (["--line", "two_units", "--live-rrd", "/tmp/x.rrd", "--view-period", "0"],
         "--view-period"),
        (["--rerun-url", "rerun+http://127.0.0.1:9876/proxy"], "--rerun-url"),
        (["--view-period", "0.05"], "--view-period"),
    ],
)  # fmt: skip
def test_run_refuses_bad_partial_line_options(args: list[str], option: str) -> None:
    """Exit 2 with one line naming the option; no process is started."""
    proc = run_cli("run", *args)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and option in err[0], proc.stderr
