"""``fence-sorter line-sim LINE --rrd FILE``: the line's Rerun recording read back with Rerun's
own reader (RrdReader) against the run's summary and the line file.

Line: config/lines/four_units.yaml (units 1 and 3 on the right, 2 and 4 mirrored on the left).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from processes import run_cli
from rrd_read import read_rrd

from fence_sorter.line.line_file import load_line
from fence_sorter.visualisation.frames import CHUTE_DEPTH, CHUTE_LENGTH

PERIOD = 0.02  # the recording's sampling period [s] (line-sim's default)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("line") / "line.rrd"
    res = run_cli(
        "line-sim", "four_units", "--parcels", "16", "--rate", "3000", "--seed", "5",
        "--rrd", str(out), "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout), read_rrd(out)


def test_one_fence_entity_per_unit_with_a_row_per_sample(recorded):
    """Every unit's fence is logged at every sample (sim time a multiple of the period, up to
    the end of the run), rooted at its axis on its own border: X = position, Y = 0 on the
    right, Y = s on a mirrored unit (view y = -Y)."""
    s, rows = recorded
    line = load_line("four_units")
    # on the period's grid, and a last sample at the end of the run if it ended between two
    grid = PERIOD * np.arange(1, int(s["sim_time_s"] / PERIOD + 1e-6) + 1)
    if s["sim_time_s"] > grid[-1] + 1e-6:
        grid = np.append(grid, s["sim_time_s"])
    for u in line.units:
        fence = rows[f"/top/units/{u.name}/fence"]
        assert len(fence) == len(grid), u.name
        ts = np.array([t for t, _ in fence])
        assert np.allclose(ts, grid, atol=1e-6)
        roots = np.array([r["strips"][0][0] for _, r in fence])
        assert np.allclose(roots[:, 0], u.position)
        assert np.allclose(roots[:, 1], -(line.width if u.mirrored else 0.0))
        # the fence swings into the belt and back: alpha_w within [0, alpha_k]
        alpha = np.array([r["scalars"][0] for _, r in rows[f"/plots/alpha_w/{u.name}"]])
        assert len(alpha) == len(grid)
        assert alpha.min() >= -1e-9 and alpha.max() <= line.planner.alpha_k + 1e-6
        assert alpha.max() > 0.5 * line.planner.alpha_k  # it made strokes


def test_every_inducted_parcel_is_drawn(recorded):
    s, rows = recorded
    ids = {label.split()[0] for _, r in rows["/top/parcels"] for label in r["labels"] or []}
    assert len(ids) == s["parcels_inducted"]


def test_sorted_parcels_end_in_a_chute_serving_their_destination(recorded):
    """Each sorted parcel's last logged footprint: its centre in the chute of a unit that
    serves its destination (the chute from the line file: CHUTE_LENGTH downstream of the
    unit's axis, beyond the border opposite its fence), within the stream's C_s offsets
    (sorted means C_s crossed the chute edge)."""
    s, rows = recorded
    line = load_line("four_units")
    last: dict[str, tuple[str, np.ndarray]] = {}
    for _, r in rows["/top/parcels"]:
        for label, strip in zip(r["labels"] or [], r["strips"], strict=True):
            pid, dest = label.split()
            last[pid] = (dest, np.array(strip[:4]).mean(axis=0) * (1.0, -1.0))
    tol = 0.1  # the stream's largest C_s offset from the box centre [m]
    inside = 0
    for dest, (x, y) in last.values():
        for u in line.units:
            if dest not in u.destinations:
                continue
            y0, y1 = (-CHUTE_DEPTH, 0.0) if u.mirrored else (line.width, line.width + CHUTE_DEPTH)
            if u.position - tol <= x <= u.position + CHUTE_LENGTH + tol and (
                y0 - tol <= y <= y1 + tol
            ):
                inside += 1
    assert s["sorted"] > 0
    assert inside == s["sorted"]


def test_parcels_on_the_loop_move_back_to_the_induction(recorded):
    """Every parcel that went round the loop is drawn on its lane while it is there, moving
    from the belt's end (X = length) back to the induction (X = 0) at length / transit_time."""
    s, rows = recorded
    line = load_line("four_units")
    seen: dict[str, list[tuple[float, float]]] = {}
    for t, r in rows["/top/loop/parcels"]:
        for label, (x, _) in zip(r["labels"] or [], r["positions"] or [], strict=True):
            seen.setdefault(label, []).append((t, x))
    assert s["recirculated"] > 0
    assert len(seen) == s["recirculated"]
    speed = line.length / line.transit_time
    for track in seen.values():
        t, x = np.array(track).T
        assert 0.0 <= x.min() and x.max() <= line.length + 1e-6
        if len(t) > 2:
            assert np.allclose(np.diff(x) / np.diff(t), -speed, rtol=1e-3)


def test_running_counters_end_at_the_summary(recorded):
    """The counters (sorted, on the line, rejected, failed) never count a sorted parcel
    back, and at the end say what the run's summary says."""
    s, rows = recorded
    texts = [r["labels"][0] for _, r in rows["/top/counters"]]
    sorted_counts = [int(text.split()[1]) for text in texts]
    assert sorted_counts == sorted(sorted_counts)
    words = texts[-1].split()
    assert int(words[1]) == s["sorted"]
    assert int(words[words.index("rejected") + 1]) == s["rejected"]
    assert int(words[words.index("failed") + 1]) == s["solver_failures"]


def test_every_parcel_drawn_carries_its_id(recorded):
    _, rows = recorded
    ids = {t: r["labels"] or [] for t, r in rows["/top/parcel_ids"]}
    for t, r in rows["/top/parcels"]:
        assert ids[t] == [label.split()[0] for label in r["labels"] or []]


def test_unit_colours_are_none_of_the_destinations_or_damage_margins():
    """The plots' unit colours stay clear (RGB distance > 60) of every destination colour,
    the fence's and the damage-margin ramp."""
    from fence_sorter.visualisation import line_view as lv
    from fence_sorter.visualisation.rerun_keys import margin_color

    others = [*lv.DESTINATION_COLORS, lv.FENCE_COLOR]
    others += [margin_color(m) for m in np.linspace(-0.5, 1.0, 1501)]
    assert min(math.dist(u, o) for u in lv.UNIT_COLORS for o in others) > 60.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--rrd", "{tmp}/line.txt"), "--rrd must be a FILE.rrd in an existing directory"),
        (("--rrd", "{tmp}/no/such/dir/line.rrd"), "--rrd must be a FILE.rrd"),
        (
            ("--rrd", "{tmp}/line.rrd", "--rrd-period", "0.001"),
            "--rrd-period must be in [0.01, 10] s",
        ),
    ],
    ids=["not-rrd", "no-directory", "period-too-short"],
)
def test_a_bad_recording_option_exits_2_with_one_line(tmp_path, args, message):
    res = run_cli("line-sim", "two_units", "--parcels", "2",
                  *(a.replace("{tmp}", str(tmp_path)) for a in args))  # fmt: skip
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], res.stderr
    assert not list(tmp_path.rglob("*.rrd"))  # nothing written
