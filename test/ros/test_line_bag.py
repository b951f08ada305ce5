"""``fence-sorter run --line LINE --bag DIR`` and ``fence-sorter analyze`` on that bag.

One run of two_units (10 parcels, seed 3) recorded (the run test_line_run.py checks against
line-sim, ``conftest.py``), then:

- ``analyze --json`` computes the line summary from the bag alone (the owner replayed on the
  recorded replies) and equals the live ``run --line --json`` summary field by field: counts
  exactly and floats bit for bit (compared as the JSON text reads back). The two wall-clock
  fields are the live run's, which the bag keeps on /line/summary: they are left out.
- the bag read a second time with the ``mcap`` package and ``mcap_ros2`` (not rosbags, not our
  reader): the lockstep records it holds agree with the live summary.
- ``fence-sorter rrd`` of the bag (its units simulated again from their recorded commands)
  writes the line view that ``line-sim --rrd`` writes of the same line, parcels and seed:
  every entity's rows equal, read back with Rerun's own reader.
- /tf_static and /robot_description cover every unit: each unit's frame sits at its position
  and side in the line frame (``routing.to_line``'s closed form).
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from processes import run_cli
from rrd_read import read_rrd

from fence_sorter.analysis.line_bag import LineBagError, replay_summary
from fence_sorter.line.handoff import INDUCTION, RECIRCULATION, link_name
from fence_sorter.line.line_file import load_line
from fence_sorter.line.multi_unit import LinePlant, LineRunConfig
from fence_sorter.line.routing import to_line
from fence_sorter.recording.bagread import read_bag
from fence_sorter.visualisation.line_view import LineRerunLogger, line_blueprint, open_recording

pytestmark = [pytest.mark.ros, pytest.mark.slow]

WALL = ("wall_time_s", "real_time_factor", "reply_wait_max_s")
CONFIG = Path(__file__).resolve().parents[2] / "config" / "lines" / "two_units.yaml"
UNITS = ["unit_1", "unit_2"]
DT = 0.01  # the line clock's step (line_owner's default)


@pytest.fixture(scope="module")
def recorded(line_run_two_units) -> tuple[Path, dict, dict[str, list]]:
    """The bag of the run (conftest.py), its live summary, every message of the bag decoded
    by mcap_ros2."""
    bag, proc = line_run_two_units
    assert proc.returncode == 0, proc.stdout + proc.stderr
    live = json.loads(proc.stdout)
    live.pop("log_dir", None)  # where the run kept its logs: not a figure of the line
    # the runner's count of processes it started again: its own, not the owner's (not on the wire)
    assert live.pop("restarts") == {"unit_1": 0, "unit_2": 0}
    messages: dict[str, list] = defaultdict(list)
    segments = sorted(bag.glob("*.mcap"))
    assert segments
    for f in segments:
        with f.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages():
                messages[channel.topic].append(msg)
    return bag, live, messages


def test_analyze_gives_the_live_summary(recorded, tmp_path: Path) -> None:
    """``analyze --json`` (and the ``line_summary.json`` of ``--out``) is the live summary."""
    bag, live, _ = recorded
    ana = run_cli("analyze", str(bag), "--json", "--out", str(tmp_path))
    assert ana.returncode == 0, ana.stderr
    got = json.loads(ana.stdout)
    assert json.loads((tmp_path / "line_summary.json").read_text()) == got
    assert {k: (v, got.get(k)) for k, v in live.items() if k not in WALL and got.get(k) != v} == {}
    assert set(got) == set(live)


def test_a_missing_reply_is_named(recorded) -> None:
    """The bag without unit_2's last step reply: the replay stops there with one line naming
    the unit, the command and the topic."""
    bag, _, _ = recorded
    contents = read_bag(bag)
    last = max(
        i for i, m in enumerate(contents.messages)
        if m.topic == "/unit_2/replies" and '"_":"Done"' in m.msg.data
    )  # fmt: skip
    del contents.messages[last]
    with pytest.raises(LineBagError, match=r"^the bag has no reply of unit_2 to its command \d+ "
                       r"\(Done missing on /unit_2/replies\)$"):  # fmt: skip
        replay_summary(contents)


def test_independent_reader_sees_the_run(recorded) -> None:
    """A step reply of every unit for every step of the clock, as many hand-offs on each link
    as the live summary counts sent, each unit's figures as the summary reports them, and the
    line file and summary of the run."""
    _, live, messages = recorded
    steps = round(live["sim_time_s"] / DT)
    for k, name in enumerate(UNITS):
        replies = [json.loads(m.data) for m in messages[f"/{name}/replies"] if m.data[:1] == "{"]
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


def test_rrd_of_the_bag_is_line_sims_view(recorded, tmp_path: Path) -> None:
    """The line view from the bag: every reply of the units simulated again equals the
    recorded one (exit 0), and each entity of the view (every unit's fence and alpha_w and N
    plots, the parcels' footprints with their labels and colours) has the rows of line-sim's
    view of two_units, 10 parcels, seed 3; so has the view ``run --line --rrd`` wrote from
    its bag."""
    bag, _, _ = recorded
    out = tmp_path / "bag.rrd"
    res = run_cli("rrd", str(bag), "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert " 0 differ " in res.stdout, res.stdout
    ref = tmp_path / "sim.rrd"
    line = load_line(CONFIG)
    plant = LinePlant(line, LineRunConfig(parcels=10, seed=3))  # line-sim --rrd, in process
    plant.warm_up()
    logger = LineRerunLogger(
        open_recording(ref, layout=lambda paused: line_blueprint(line, paused)), line
    )
    plant.observers.append(logger.observe)
    plant.run()
    logger.close(plant)
    got, want = read_rrd(out), read_rrd(ref)
    entities = [e for e in want if e.startswith(("/top/", "/plots/"))]
    assert {f"/top/units/{u}/fence" for u in UNITS} <= set(entities)
    assert "/top/parcels" in entities
    run = read_rrd(bag.with_suffix(".rrd"))
    for e in entities:
        assert got[e] == want[e], e
        assert run[e] == want[e], e


def _matrix(tf) -> np.ndarray:
    """The 4x4 homogeneous matrix of a geometry_msgs/Transform."""
    x, y, z, w = tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w
    m = np.eye(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = [tf.translation.x, tf.translation.y, tf.translation.z]
    return m


def test_tf_and_urdf_cover_every_unit(recorded) -> None:
    """/tf_static: line -> <unit>/sorter carries a point and a heading of the unit's frame to
    where ``to_line`` puts them (right: X = x + position, Y = y; left: Y = s - y, yaw
    negated), and each unit's fixed frames (belt, chute, scan line) hang off it; the URDF has
    every unit's links under its prefix, mounted on ``line``."""
    _, _, messages = recorded
    line = load_line(CONFIG)
    (static,) = messages["/tf_static"]
    tfs = {(t.header.frame_id, t.child_frame_id): t.transform for t in static.transforms}
    for u in line.units:
        m = _matrix(tfs[("line", f"{u.name}/sorter")])
        for x, y, yaw in ((0.0, 0.0, 0.0), (0.8, 0.3, 0.4), (-2.0, 0.65, -1.1)):
            got = m @ [x, y, 0.0, 1.0]
            heading = m[:3, :3] @ [math.cos(yaw), math.sin(yaw), 0.0]
            ex, ey, eyaw = to_line(u.position, u.mirrored, line.width, x, y, yaw)
            closed = (x + u.position, line.width - y if u.mirrored else y)
            assert got[:2] == pytest.approx(closed, abs=1e-12) and closed == (ex, ey)
            assert got[2] == pytest.approx(0.0, abs=1e-12)
            assert math.atan2(heading[1], heading[0]) == pytest.approx(eyaw, abs=1e-12)
        for child in ("belt", "chute", "scan_line"):
            assert (f"{u.name}/sorter", f"{u.name}/{child}") in tfs
    (desc,) = messages["/robot_description"]
    root = ET.fromstring(desc.data)
    links = {e.get("name") for e in root.iter("link")}
    for u in line.units:
        assert {f"{u.name}/{n}" for n in ("sorter", "belt", "chute", "fence")} <= links
        (mount,) = [j for j in root.iter("joint") if j.get("name") == f"{u.name}/mount"]
        assert mount.find("parent").get("link") == "line"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--no-owner", "--bag", "{tmp}/bag"], "--bag records on the owner's host"),
        (["--bag", "{tmp}/file"], "--bag must be a directory"),
    ],
    ids=["no-owner", "a-file"],
)
def test_a_bad_bag_option_exits_2_with_one_line(tmp_path: Path, args, message) -> None:
    """--bag with --no-owner, or on a file: exit 2, one line naming --bag, nothing started
    and nothing written."""
    (tmp_path / "file").write_text("")
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    proc = run_cli("run", "--line", "two_units", *args)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and message in err[0], proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]
