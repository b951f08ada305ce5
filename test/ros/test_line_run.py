"""``fence-sorter run --line``: the line's nodes started by the runner as separate processes on
an isolated domain, compared with ``fence-sorter line-sim`` on the same line, parcels and seed.

The lockstep clock makes the two summaries equal field by field (the wall-clock fields aside):
the same strokes, declines, forces and link counts, over DDS as in one process.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from processes import run_cli

pytestmark = [pytest.mark.ros, pytest.mark.slow]

WALL = ("wall_time_s", "real_time_factor")


def test_run_line_equals_line_sim(line_run_two_units) -> None:
    """two_units, 10 parcels, seed 3 (recorded: the run of conftest.py, its bag for
    test_line_bag.py): exit 0, the --json summary equals line-sim's, every parcel inducted
    ends sorted or rejected (conservation exact), and on every link the hand-offs received by
    the downstream process equal those its upstream one sent."""
    sim = run_cli("line-sim", "two_units", "--parcels", "10", "--seed", "3", "--json")
    assert sim.returncode == 0, sim.stderr
    ref = json.loads(sim.stdout)
    _, proc = line_run_two_units
    assert proc.returncode == 0, proc.stdout + proc.stderr
    got = json.loads(proc.stdout)
    assert {k: (v, got.get(k)) for k, v in ref.items() if k not in WALL and got.get(k) != v} == {}
    assert got["parcels_inducted"] == 10 == got["sorted"] + got["rejected"] + got["still_on_line"]
    assert got["conservation_ok"] and got["drained"] and got["handoffs_balanced"]
    for link, v in got["links"].items():
        assert v["sent"] == v["received"] > 0 and v["lost"] == 0, link


def test_run_line_paced_with_line_sim_s_options_equals_line_sim(tmp_path: Path) -> None:
    """--duration, --rate and --no-guard mean what they mean to line-sim, and --rtf paces the
    line clock without changing a figure: two_units, 4 s of induction at 4000 pcs/h, guard
    off (the units' strokes then hit parcels: intrusions counted, the parcels go round),
    paced at 5x real time: the summary equals line-sim's with the same options, and the
    owner's pacing block counts every 10 ms step of the clock as a cycle of its grid."""
    opts = ["--duration", "4", "--rate", "4000", "--no-guard", "--seed", "3", "--json"]
    sim = run_cli("line-sim", "two_units", *opts)
    ref = json.loads(sim.stdout)
    assert not ref["guard"] and ref["swept_sector_intrusions"] > 0, sim.stderr
    assert ref["parcels_inducted"] == 5  # 4 s at 4000 pcs/h, the stream's drawn arrivals
    proc = run_cli(
        "run", "--line", "two_units", *opts, "--rtf", "5", "--log-dir", str(tmp_path / "logs"),
        timeout=600,
    )  # fmt: skip
    assert proc.returncode == sim.returncode, proc.stdout + proc.stderr
    got = json.loads(proc.stdout)
    assert {k: (v, got.get(k)) for k, v in ref.items() if k not in WALL and got.get(k) != v} == {}
    p = got["pacing"]
    assert p["real_time_factor_target"] == 5.0 and p["period_s"] == pytest.approx(0.01 / 5)
    assert p["steps"] == round(got["sim_time_s"] / 0.01)
    # every deadline of the grid is a cycle, run or missed: the steps plus those a slip dropped
    assert p["cycles"] >= p["steps"] and 0 <= p["deadline_misses"] <= p["cycles"]
    assert p["deadline_miss_share"] == pytest.approx(p["deadline_misses"] / p["cycles"])
    # the hand-offs' transit was measured on every link, once per hand-off received there (a
    # link that carried none has no transit figures)
    lat = got["handoff_latency"]
    for link, v in got["links"].items():
        assert lat[link]["n"] == v["sent"]
        if v["sent"]:
            assert 0.0 <= lat[link]["p50_ms"] <= lat[link]["max_ms"]
    assert any(v["sent"] for v in got["links"].values())


def test_run_line_refuses_a_bad_line_file(tmp_path: Path) -> None:
    """A line file with a bad key: exit 2, one line naming the key, no process started."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("conveyor: {speed: 99}\n")
    proc = run_cli("run", "--line", str(bad), "--parcels", "3")
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "conveyor.speed" in err[0], proc.stderr


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--sensors", "camera60"], "--sensors does not go with --line"),
        (["--rrd", "x.txt"], "--rrd must be a .rrd file in an existing directory"),
        (["--rrd", "x.rrd", "--no-owner"], "--rrd is written on the owner's host"),
        (["--stream", "x"], "--stream"),
        (["--parcels", "0"], "--parcels"),
    ],
)
def test_run_line_refuses_what_a_line_run_does_not_take(args: list[str], option: str) -> None:
    """A single-unit option, or a parcel count out of range: exit 2, one line naming it."""
    proc = run_cli("run", "--line", "two_units", *args)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and option in err[0], proc.stderr
