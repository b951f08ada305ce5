"""`fence-sorter calibrate-bench` refuses bad options before any work: exit 2, one line
naming the option and its allowed range."""

from __future__ import annotations

import pytest

from fence_sorter.cli import main as cli_main


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [
        ("--seeds", "-1", "[0, inf)"),
        ("--parcels", "2", "[3, inf)"),
        ("--timing-parcels", "-5", "[0, inf)"),
        ("--workers", "0", "[1, inf)"),
    ],
)
def test_bad_option_exits_2_naming_it(capsys, option, value, allowed) -> None:
    code = cli_main.main(["calibrate-bench", option, value])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1
    assert option in err[0] and allowed in err[0] and value in err[0]
