"""The start-up command's bad options: exit 2 with one line naming the option and its range,
before anything is measured."""

from __future__ import annotations

import pytest

from benchmarks import startup


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--rounds", "0"], "--rounds must be >= 1, got 0"),
        (["--runs", "-1"], "--runs must be >= 0, got -1"),
        (["--load", "-2"], "--load must be >= 0, got -2"),
        (["--scene", "nope"], "--scene: unknown scene 'nope'; one of "),
    ],
)
def test_bad_option_exits_2_naming_it(argv, message, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        startup.main([*argv, "--out", ""])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1]
    assert "impact_flexible" in err[-1] or "--scene" not in message
