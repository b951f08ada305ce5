"""`python -m benchmarks calibrate-bench` refuses bad options before any work: exit 2, one line
naming the option and its allowed range; --from-json renders an earlier run's figures."""

from __future__ import annotations

import json

import pytest

from benchmarks import cli as cli_main
from benchmarks.calibrate_bench import BEGIN, END, TRUTH


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [
        ("--seeds", "-1", "[0, inf)"),
        ("--parcels", "2", "[3, inf)"),
        ("--timing-parcels", "-5", "[0, inf)"),
        ("--workers", "0", "[1, inf)"),
        ("--draws", "0", "[1, inf)"),
        ("--fresh-noise", "105,x", "[0, inf)"),
        ("--fresh-noise", "-3", "[0, inf)"),
    ],
)
def test_bad_option_exits_2_naming_it(capsys, option, value, allowed) -> None:
    code = cli_main.main(["calibrate-bench", option, value])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1
    assert option in err[0] and allowed in err[0] and value in err[0]


def _row(seed: int, z: float) -> dict:
    est = {"value": 1.0, "ci95": [0.9, 1.1], "inside": abs(z) <= 1.96, "z": z,
           "verdict": "identified"}  # fmt: skip
    return {"seed": seed, **{n: est for n in TRUTH}}


def test_from_json_renders_the_measured_figures_with_their_command(tmp_path, capsys) -> None:
    """--from-json renders an earlier run's figures (command, commit, per-seed z with the
    misses in bold) into the doc's generated section, and nothing else of the doc."""
    n = len(TRUTH)
    report = {
        "command": "nice -n 10 python -m benchmarks calibrate-bench --seeds 2",
        "commit": "abc1234",
        "machine": {"arch": "riscv64", "cpus": 64},
        "coverage": {"seeds": 2, "parcels": 8, "share_inside": dict.fromkeys(TRUTH, 0.5),
                     "share_inside_first": dict.fromkeys(TRUTH, 0.5),
                     "rms_z": dict.fromkeys(TRUTH, 1.8), "median_rel_halfwidth":
                     dict.fromkeys(TRUTH, 0.001), "rows": [_row(100, 0.5), _row(101, -2.5)]},
        "flag": {},
    }  # fmt: skip
    src = tmp_path / "bench.json"
    src.write_text(json.dumps(report), encoding="utf-8")
    doc = tmp_path / "doc.md"
    doc.write_text(f"before\n\n{BEGIN}\nstale figures\n{END}\n\nafter\n", encoding="utf-8")
    assert cli_main.main(["calibrate-bench", "--from-json", str(src), "--doc", str(doc)]) == 0
    text = doc.read_text(encoding="utf-8")
    assert text.startswith("before\n") and text.endswith("\nafter\n")
    assert "stale figures" not in text
    assert "`nice -n 10 python -m benchmarks calibrate-bench --seeds 2` at abc1234" in text
    assert "at abc1234 (riscv64, 64 CPUs)." in text  # the machine of the JSON, not this one
    assert "| 100 | " + " | ".join(["+0.50"] * n) + " |" in text
    assert "| 101 | " + " | ".join(["**-2.50**"] * n) + " |" in text
    assert "50 % (1 of 2; " in text
    capsys.readouterr()
    assert cli_main.main(["calibrate-bench", "--from-json", str(doc)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--from-json" in err[0]


def test_from_json_renders_blocks_the_first_seeds_later_misses_and_fresh_noise(
    tmp_path, capsys
) -> None:
    """Forty seeds: the table lists the first 20 and, of the later ones, only those with a
    miss; each parameter's count per block of 20 seeds; the fresh-noise rows."""
    rows = [_row(100 + i, -2.5 if i in (3, 27) else 0.1) for i in range(40)]
    fresh = {
        "draws": 50,
        "parcels": 8,
        "seeds": [
            {
                "seed": 105,
                "draws": 50,
                "share_inside": dict.fromkeys(TRUTH, 0.94),
                "rms_z": dict.fromkeys(TRUTH, 1.03),
                "mean_z": dict.fromkeys(TRUTH, 0.0),
            }
        ],
    }
    report = {"command": "c", "commit": "abc1234", "machine": {"arch": "x86_64", "cpus": 2},
              "fresh_noise": fresh,
              "coverage": {"seeds": 40, "parcels": 8, "rows": rows}}  # fmt: skip
    src = tmp_path / "bench.json"
    src.write_text(json.dumps(report), encoding="utf-8")
    assert cli_main.main(["calibrate-bench", "--from-json", str(src)]) == 0
    text = capsys.readouterr().out
    coverage = text.split("**Fresh noise")[0]
    listed = [line.split(" | ")[0][2:] for line in coverage.splitlines()
              if line.startswith("| 1") and line.count("|") == len(TRUTH) + 2]  # fmt: skip
    assert listed == [str(100 + i) for i in range(20)] + ["127"]
    assert "(1 of 20)" in text  # later misses: seed 127 alone
    assert f"- {next(iter(TRUTH))}: 19, 19" in text
    assert "95 % (38 of 40; " in text
    assert "| 105 | " + " | ".join(["94 % (1.03)"] * len(TRUTH)) + " |" in text
