"""``python -m benchmarks line-speed``: runs of one seeded stream, their sim / wall and sim /
CPU figures with the load beside them and the medians, written with the command and commit;
bad options exit 2 with one line naming the option and its allowed range."""

from __future__ import annotations

import json
import statistics

import pytest

from benchmarks import cli as cli_main


def test_runs_give_the_same_line_and_their_median_speed(tmp_path, capsys) -> None:
    md, js = tmp_path / "line-speed.md", tmp_path / "line-speed.json"
    argv = ["line-speed", "two_units", "--runs", "2", "--duration", "10", "--seed", "4"]
    assert cli_main.main([*argv, "--out", str(md), "--json", str(js)]) == 0
    data = json.loads(js.read_text())
    command = "python -m benchmarks line-speed two_units --runs 2 --rate 6000 --duration 10"
    assert data["command"] == command + " --seed 4"
    assert data["commit"] and data["cpus"] >= 1
    runs = data["runs"]
    assert len(runs) == 2 and data["figures_same_in_every_run"]
    for r in runs:
        assert r["sim_s"] == data["figures"]["sim_time_s"] > 10.0  # the stream and its drain
        assert r["sim_per_wall"] == r["sim_s"] / r["wall_s"]
        assert r["sim_per_cpu"] == r["sim_s"] / r["cpu_s"]
        assert r["load_before"] >= 0.0 and r["load_after"] >= 0.0
    assert data["median_sim_per_wall"] == statistics.median(r["sim_per_wall"] for r in runs)
    text = md.read_text()
    assert text.startswith("# Line speed (two_units)") and f"`{data['command']}`" in text
    assert f"{data['median_sim_per_wall']:.1f}x real time" in text
    assert capsys.readouterr().out.count("run ") == 2


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [("--runs", "0", "[1, 100]"), ("--rate", "0", "[1, 100000]"),
     ("--duration", "0", "[1, 100000]")],
)  # fmt: skip
def test_bad_option_exits_2_naming_it(tmp_path, capsys, option, value, allowed) -> None:
    out = tmp_path / "x.md"
    argv = ["line-speed", option, value, "--out", str(out), "--json", str(tmp_path / "x.json")]
    assert cli_main.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0] and allowed in err[0]
    assert not out.exists()
