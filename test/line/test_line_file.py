"""Line files (config/lines): the shipped lines load; every bad key is one LineError naming it,
and the command line turns it into exit 2."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from fence_sorter.cli.main import main
from fence_sorter.line.line_file import UNIT_LEAD, UNIT_TAIL, LineError, load_line
from fence_sorter.resources import data_path

FOUR = data_path("config", "lines", "four_units.yaml")


def test_four_units_shipped():
    line = load_line("four_units")
    assert len(line.units) == 4
    assert len(line.destinations) == 8
    assert math.isclose(sum(line.destinations.values()), 1.0)
    assert {u.side for u in line.units} == {"left", "right"}
    # every destination served, zones on the belt and apart
    assert {d for u in line.units for d in u.destinations} == set(line.destinations)
    for a, b in zip(line.units, line.units[1:], strict=False):
        assert b.position - a.position >= UNIT_LEAD + UNIT_TAIL
    # the line's conveyor is the units' conveyor; a per-unit override reaches its scene
    for u in line.units:
        assert u.scenario.conveyor.belt_speed == line.speed
        assert u.scenario.conveyor.width == line.width
    assert line.units[3].scenario.fence is None  # unit_4: fence.type stiff
    assert line.units[0].scenario.fence is not None


def test_two_units_shipped():
    line = load_line("two_units")
    assert [u.side for u in line.units] == ["right", "left"]
    assert line.units[1].chute_capacity == 1000
    assert [u.name for u in line.serving("C")] == ["unit_1", "unit_2"]


def _write(tmp_path: Path, raw: dict) -> Path:
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(raw))
    return p


def _raw() -> dict:
    return yaml.safe_load(FOUR.read_text())


def _bad(tmp_path, mutate, *needles):
    raw = _raw()
    mutate(raw)
    path = _write(tmp_path, raw)
    with pytest.raises(LineError) as exc:
        load_line(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("line bad.yaml: ")
    for n in needles:
        assert n in msg, msg
    return msg


def test_overlapping_units(tmp_path):
    def m(raw):
        raw["units"][1]["position"] = 6.0  # 3 m after unit_1: zones overlap

    _bad(tmp_path, m, "units.unit_2.position", "overlaps units.unit_1", ">= 8 m")


def test_destination_no_unit_serves(tmp_path):
    def m(raw):
        raw["units"][0]["destinations"] = ["D1"]

    _bad(tmp_path, m, "induction.destinations.D2", "no unit serves it")


def test_unit_destination_not_inducted(tmp_path):
    def m(raw):
        raw["units"][0]["destinations"] = ["D1", "D2", "X9"]

    _bad(tmp_path, m, "units.unit_1.destinations", "'X9'", "allowed: D1")


def test_unit_outside_belt(tmp_path):
    def m(raw):
        raw["units"][3]["position"] = 23.0

    _bad(tmp_path, m, "units.unit_4.position must be in [2, 21] m", "got 23")


def test_unknown_keys(tmp_path):
    _bad(tmp_path, lambda r: r.update(belt={}), "line.belt is not a known key")
    _bad(tmp_path, lambda r: r["units"][0].update(colour=1), "units[0].colour is not a known key")
    _bad(tmp_path, lambda r: r["recirculation"].update(loops=2), "recirculation.loops")


def test_bad_values(tmp_path):
    _bad(tmp_path, lambda r: r["units"][0].update(side="up"), "units[0].side", "right, left")
    _bad(
        tmp_path,
        lambda r: r["induction"].update(no_read_share=1.5),
        "induction.no_read_share must be in [0, 1]",
    )
    _bad(
        tmp_path,
        lambda r: r["induction"].update(min_gap=-0.5),
        "induction.min_gap must be in [0, 10]",
    )
    _bad(
        tmp_path,
        lambda r: r["recirculation"].update(max_passes=0),
        "recirculation.max_passes must be an integer in [1, 15]",
    )
    _bad(
        tmp_path,
        lambda r: r["induction"]["destinations"].update(D1=0.5),
        "shares must sum to 1",
    )
    # a unit's scene override is checked by the scene's own validation, key named
    _bad(
        tmp_path,
        lambda r: r["units"][0].update(overrides={"drive.alpha_k_deg": 120}),
        "units[0]",
        "drive.alpha_k_deg must be in (0, 90] deg",
    )
    _bad(
        tmp_path,
        lambda r: r["units"][0].update(overrides={"conveyor.belt_speed": 2}),
        "units[0].overrides.conveyor.belt_speed",
    )


def test_cli_exit_2(tmp_path, capsys):
    raw = _raw()
    raw["units"][1]["position"] = 6.0
    code = main(["line-sim", str(_write(tmp_path, raw))])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "units.unit_2.position" in err[0]
    assert main(["line-sim", str(tmp_path / "missing.yaml")]) == 2
    assert main(["line-sim", "two_units", "--rate", "0"]) == 2
