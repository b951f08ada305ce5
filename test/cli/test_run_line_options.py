"""``fence-sorter run --line`` with line-sim's options (--duration, --rate, --no-guard), --rtf
and the fault timeouts (--reply-timeout, --owner-timeout): a bad value, or one of them without
--line, exits 2 with one line naming the option and its allowed range; nothing is started (the
checks come before any process)."""

from __future__ import annotations

import pytest

from fence_sorter.cli.main import main


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--rtf", "-1"], "--rtf must be in [0, 100]"),
        (["--rtf", "101"], "--rtf must be in [0, 100]"),
        (["--rtf", "nan"], "--rtf must be in [0, 100]"),
        (["--duration", "0"], "--duration must be in (0, 1e6] s"),
        (["--duration", "-3"], "--duration must be in (0, 1e6] s"),
        (["--rate", "0"], "--rate must be in [1, 100000] pcs/h"),
        (["--rate", "2e5"], "--rate must be in [1, 100000] pcs/h"),
        (["--reply-timeout", "0.5"], "--reply-timeout must be in [1, 3600] s, got 0.5"),
        (["--reply-timeout", "4000"], "--reply-timeout must be in [1, 3600] s"),
        (["--reply-timeout", "nan"], "--reply-timeout must be in [1, 3600] s"),
        # the units wait for the owner while it waits for one of them: above --reply-timeout
        (["--owner-timeout", "10"], "--owner-timeout must be in (10, 3600] s"),
        (
            ["--reply-timeout", "30"],
            "--owner-timeout must be in (30, 3600] s (above --reply-timeout), got 20",
        ),
        (["--reply-timeout", "2", "--owner-timeout", "inf"], "--owner-timeout must be in (2, "),
        (["--no-owner", "--owner-timeout", "0.5"], "--owner-timeout must be in [1, 3600] s"),
        (["--no-owner", "--reply-timeout", "5"], "--reply-timeout is the owner's"),
    ],
)
def test_a_bad_value_exits_2_naming_the_option_and_its_range(
    args: list[str], expected: str, capsys: pytest.CaptureFixture
) -> None:
    assert main(["run", "--line", "two_units", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--no-guard"], "--no-guard"),
        (["--reply-timeout", "5"], "--reply-timeout"),
        (["--owner-timeout", "30"], "--owner-timeout"),
    ],
)
def test_line_sim_s_options_go_with_line_only(
    args: list[str], option: str, capsys: pytest.CaptureFixture
) -> None:
    assert main(["run", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"fence-sorter: error: {option} goes with --line only"]
