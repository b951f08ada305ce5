"""``python -m benchmarks.versus``: bad arguments exit 2 with one line; the
child processes solve the scene of the tree they are given; the report renders from its JSON.
No timing assertions (the figures are the command's output, not a test's)."""

from __future__ import annotations

import pytest

from benchmarks import REPO, versus
from fence_sorter.verification.report import tables


@pytest.mark.parametrize(
    "argv, message",
    [
        (["no-such-commit-xyz"], "BASE must be a commit of this repository"),
        (["HEAD", "--scenes", "nowhere"], "unknown bench scene 'nowhere'"),
        (["HEAD", "--rounds", "0"], "--rounds must be in [1, 100], got 0"),
        (["HEAD", "--calls", "0"], "--calls must be in [1, 10000], got 0"),
    ],
)
def test_bad_arguments_exit_2_naming_them(argv, message, capsys) -> None:
    assert versus.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("versus: error: ") and message in err[0]


@pytest.mark.slow
def test_rounds_alternate_fresh_processes_of_each_tree() -> None:
    """The same tree on both sides: every call is counted, each round gives a ratio, and both
    sides solved the same event (the same peak force to the last bit)."""
    rows = versus.measure(
        {"head": REPO, "base": REPO}, ["positioned_stiff"], rounds=2, calls=2, warm_up=1,
        log=lambda m: None,
    )  # fmt: skip
    (row,) = rows
    assert row["calls"] == {"head": 4, "base": 4}
    assert len(row["round_ratios"]) == 2 and all(r > 0 for r in row["round_ratios"])
    assert row["peak_force"]["head"] == row["peak_force"]["base"] > 0


def test_report_renders_from_its_json() -> None:
    data = {
        "command": "python -m benchmarks.versus abc1234",
        "finished": "2026-01-01 10:00 UTC",
        "head": "def5678",
        "base": "abc1234",
        "rounds": 2,
        "calls": 3,
        "warm_up": 3,
        "load_before": "0.10 0.20 0.30",
        "load_after": "0.40 0.50 0.60",
        "machine": {"cpu": "Test CPU"},
        "scenes": [
            {
                "scene": "positioned_stiff",
                "calls": {"head": 6, "base": 6},
                "median_ms": {"head": 0.25, "base": 0.5},
                "peak_force": {"head": 65.4544, "base": 65.4544},
                "ratio": 0.5,
                "round_ratios": [0.45, 0.55],
            }
        ],
    }
    assert tables(versus.render(data)) == [
        [
            "| scene | def5678 median [ms] | abc1234 median [ms] | ratio "
            "| ratio per round (min - max) | peak N [N] (both) |",
            "|---|---|---|---|---|---|",
            "| positioned_stiff | 0.250 | 0.500 | 0.500 | 0.450 - 0.550 | 65.4544 / 65.4544 |",
        ],
        ["| machine |  |", "|---|---|", "| cpu | Test CPU |"],
    ]
