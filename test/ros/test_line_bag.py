"""``fence-sorter run --line LINE --bag DIR`` and ``fence-sorter analyze`` on that bag.

One run of two_units (10 parcels, seed 3) recorded, then:

- ``analyze --json`` computes the line summary from the bag alone (the owner replayed on the
  recorded replies) and equals the live ``run --line --json`` summary field by field: counts
  exactly and floats bit for bit (compared as the JSON text reads back). The two wall-clock
  fields are the live run's, which the bag keeps on /line/summary: they are left out.
- the bag read a second time with the ``mcap`` package and ``mcap_ros2`` (not rosbags, not our
  reader): the lockstep records it holds agree with the live summary.
"""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from processes import run_cli

from fence_sorter.line.handoff import INDUCTION, RECIRCULATION, link_name

pytestmark = [pytest.mark.ros, pytest.mark.slow]

WALL = ("wall_time_s", "real_time_factor")
CONFIG = Path(__file__).resolve().parents[2] / "config" / "lines" / "two_units.yaml"
UNITS = ["unit_1", "unit_2"]
DT = 0.01  # the line clock's step (line_owner's default)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[Path, dict, dict[str, list]]:
    """The bag, the live summary, every message of the bag decoded by mcap_ros2."""
    bag = tmp_path_factory.mktemp("line_bag") / "bag"
    proc = run_cli(
        "run", "--line", "two_units", "--parcels", "10", "--seed", "3", "--json",
        "--bag", str(bag), timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    live = json.loads(proc.stdout)
    messages: dict[str, list] = defaultdict(list)
    segments = sorted(bag.glob("*.mcap"))
    assert segments
    for f in segments:
        with f.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages():
                messages[channel.topic].append(msg)
    return bag, live, messages


def test_analyze_gives_the_live_summary(recorded) -> None:
    bag, live, _ = recorded
    ana = run_cli("analyze", str(bag), "--json")
    assert ana.returncode == 0, ana.stderr
    got = json.loads(ana.stdout)
    assert {k: (v, got.get(k)) for k, v in live.items() if k not in WALL and got.get(k) != v} == {}
    assert set(got) == set(live)


def test_independent_reader_sees_the_run(recorded) -> None:
    """A step reply of every unit for every step of the clock, as many hand-offs on each link
    as the live summary counts sent, each unit's figures as the summary reports them, and the
    line file and summary of the run."""
    _, live, messages = recorded
    steps = round(live["sim_time_s"] / DT)
    for k, name in enumerate(UNITS):
        replies = [json.loads(m.data) for m in messages[f"/{name}/replies"] if m.data != "ready"]
        kinds = Counter(r["_"] for r in replies)
        assert kinds["Done"] == steps, name
        (figures,) = [r for r in replies if r["_"] == "Figures"]
        for key in ("strokes", "sorted", "missed", "peak_normal_force_N"):
            assert figures["figures"][key] == live["units"][name][key], (name, key)
        down = RECIRCULATION if k == len(UNITS) - 1 else k + 1
        sent = live["links"][link_name(k, down, UNITS)]["sent"]
        assert len(messages[f"/{name}/handoffs"]) == sent > 0, name
    sent = live["links"][link_name(INDUCTION, 0, UNITS)]["sent"]
    assert len(messages["/line/handoffs"]) == sent > 0
    (setup,) = [json.loads(m.data) for m in messages["/line/setup"]]
    assert setup["line_text"] == CONFIG.read_text(encoding="utf-8")
    (summary,) = [json.loads(m.data) for m in messages["/line/summary"]]
    assert summary["sorted"] == live["sorted"] and summary["units"] == live["units"]


def test_line_bag_needs_the_owner_here() -> None:
    """--bag with --no-owner: exit 2, one line naming --bag, no process started."""
    proc = run_cli("run", "--line", "two_units", "--no-owner", "--bag", "x")
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and "--bag" in err[0], proc.stderr
