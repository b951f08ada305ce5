"""``python -m benchmarks planner-latency``: per rate and planner setting, the strokes' plant
figures against (8), (10)-(12), declines and latency, written with the command and commit;
bad options exit 2 with one line naming the option and its allowed range."""

from __future__ import annotations

import json

import pytest

from benchmarks import cli as cli_main


@pytest.mark.slow
def test_each_setting_is_planned_and_run_on_the_plant(tmp_path, capsys) -> None:
    md, js = tmp_path / "planner.md", tmp_path / "planner.json"
    argv = ["planner-latency", "--parcels", "4", "--rate-factor", "1", "--warmup-time", "0.2"]
    assert cli_main.main([*argv, "--out", str(md), "--json", str(js)]) == 0
    data = json.loads(js.read_text())
    assert data["command"] == (
        "python -m benchmarks planner-latency --scene impact_flexible --belt-speed 2 "
        "--stream mixed --rate-factor 1 --parcels 4 --warmup-time 0.2"
    )
    assert data["commit"] and [r["rate_pcs_h"] for r in data["runs"]] == [4000.0]
    settings = data["runs"][0]["settings"]
    assert len(settings) == 4
    for r in settings.values():
        declined = sum(r["declines"].values())
        assert r["parcels"] == 4 and r["strokes"] + declined == 4  # every one divert
        assert set(r["over_limit_on_plant"]) == {"8", "10", "11", "12"}
    # the planner verified on the plant: no stroke over a limit there
    default = settings["plant + uncertainty set (default)"]
    assert default["strokes"] >= 1 and sum(default["over_limit_on_plant"].values()) == 0
    assert default["worst_on_plant"]["exit_speed"] <= 2.5
    assert default["latency_p50_ms"] <= default["latency_max_ms"]
    text = md.read_text()
    assert text.startswith("# Planner: strokes on the plant") and f"`{data['command']}`" in text
    assert "## 1x the stream's rate: 4000 pcs/h" in text
    assert capsys.readouterr().out.count("x1 ") == 4


@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [("--rate-factor", "0", "[0.1, 20]"), ("--rate-factor", "1,x", "[0.1, 20]"),
     ("--parcels", "0", "[1, 100000]"), ("--belt-speed", "20", "[0.1, 10]"),
     ("--warmup-time", "-1", "[0, 600]")],
)  # fmt: skip
def test_bad_option_exits_2_naming_it(tmp_path, capsys, option, value, allowed) -> None:
    out, js = tmp_path / "x.md", tmp_path / "x.json"
    argv = ["planner-latency", option, value, "--out", str(out), "--json", str(js)]
    assert cli_main.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0] and allowed in err[0]
    assert not out.exists()
