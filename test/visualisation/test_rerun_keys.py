"""The example run's Rerun recording (``fence-sorter rrd``'s logging) read back with Rerun's
own reader: every parcel's outcome mark, the two colour schemes and their legend, the scale
bar, the belt's direction, one timeline and the recording's end at the run's last outcome."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rrd_read import read_rrd

from fence_sorter.visualisation import rerun_keys as keys

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "bags" / "example_4_parcels"
#: /sort_outcomes reason codes of the message (msg/SortOutcome)
CODE_OUTCOME = {0: "sorted", 1: "passed", 4: "missed"}


def rgb(packed: int) -> tuple[int, int, int]:
    """A Rerun colour (0xRRGGBBAA) as (r, g, b)."""
    return ((packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255)


def read_static(path: Path) -> dict[str, dict]:
    """Per entity: its static components."""
    from rerun.chunk import RrdReader

    out: dict[str, dict] = {}
    for chunk in RrdReader(path).stream():
        if chunk.is_static:
            batch = chunk.to_record_batch()
            row = {c.split(":")[-1]: batch.column(c).to_pylist()[-1] for c in batch.schema.names
                   if ":" in c}  # fmt: skip
            out.setdefault(chunk.entity_path, {}).update(row)
    return out


def timelines(path: Path) -> set[str]:
    from rerun.chunk import RrdReader

    names = set()
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            names |= {c for c in chunk.to_record_batch().schema.names if ":" not in c}
    return names - {"rerun.controls.RowId"}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from fence_sorter.recording.bagread import read_bag
    from fence_sorter.stamps import time_to_sec
    from fence_sorter.visualisation.frames import scene_from_bag
    from fence_sorter.visualisation.rerun_bag import log_bag
    from fence_sorter.visualisation.rerun_layout import open_recording

    contents = read_bag(EXAMPLE)
    out = tmp_path_factory.mktemp("views") / "example.rrd"
    scene = scene_from_bag(contents)
    log_bag(contents, open_recording(out, scene=scene)).close()
    outcomes = {
        int(m.msg.parcel_id): (CODE_OUTCOME.get(int(m.msg.reason_code), "failed"),
                               time_to_sec(m.msg.header.stamp))
        for m in contents.by_topic("/sort_outcomes")
    }  # fmt: skip
    fence_end = max(time_to_sec(m.msg.header.stamp) for m in contents.by_topic("/fence_state"))
    return scene, outcomes, fence_end, read_rrd(out), read_static(out), out


def test_every_parcel_ends_with_one_outcome_mark_where_it_left(recorded):
    """At the end one mark per parcel, in its outcome's colour: sorted ones at the chute's
    border (C_s crossed y0 = s), the one that passed at the belt's end."""
    scene, outcomes, _, rows, _, _ = recorded
    t, last = rows["/top/outcomes"][-1]
    ids = [int(label.split(":")[0]) for label in last["labels"]]
    assert sorted(ids) == sorted(outcomes)  # each parcel once
    assert t == pytest.approx(max(t for _, t in outcomes.values()))
    for pid, label, colour, (x, vy) in zip(
        ids, last["labels"], last["colors"], last["positions"], strict=True
    ):
        outcome = outcomes[pid][0]
        assert label == f"{pid}: {outcome}"
        assert rgb(colour) == keys.OUTCOME_COLORS[outcome]
        y = -vy  # view y is -y0
        if outcome == "sorted":
            assert abs(y - scene.belt_width) < 0.3
            assert abs(x - scene.chute[0]) < 0.5 * scene.chute[2]
        elif outcome == "passed":
            assert x > scene.belt_x[1] - 0.3 and 0.0 < y < scene.belt_width
    # each mark appears at its parcel's outcome time, not before
    for t, row in rows["/top/outcomes"]:
        shown = {int(label.split(":")[0]) for label in row["labels"]}
        assert shown == {pid for pid, (_, to) in outcomes.items() if to <= t + 1e-9}


def test_outcome_and_margin_schemes_share_no_colour(recorded):
    """Outlines and outcome marks draw from one scheme, damage marks from the margin ramp;
    the nearest pair across the two is far apart (RGB distance > 80)."""
    _, _, _, rows, static, _ = recorded
    outcome = set(keys.OUTCOME_COLORS.values()) | set(keys.PARCEL_COLORS.values())
    ramp = [keys.margin_color(m) for m in np.linspace(-0.5, 1.0, 1501)]
    nearest = min(math.dist(a, b) for a in outcome for b in ramp)
    assert nearest > 80.0
    drawn = {rgb(c) for _, r in rows["/top/parcels"] for c in r["colors"] or []}
    assert drawn and drawn <= set(keys.PARCEL_COLORS.values())
    marks = {rgb(c) for _, r in rows["/top/damage_risk"] for c in r["colors"]}
    assert marks and all(min(math.dist(m, r) for r in ramp) < 3.0 for m in marks)
    # the legend shows both schemes, with words for each colour
    legend_outcome = {rgb(c) for c in static["/top/legend/outcome"]["colors"]}
    assert legend_outcome == outcome
    legend_margin = [rgb(c) for c in static["/top/legend/margin"]["colors"]]
    assert legend_margin == [keys.margin_color(m) for m, _ in keys.MARGIN_KEYS]
    words = " ".join(static["/top/legend/labels"]["labels"])
    for name in (*keys.OUTCOME_COLORS, *keys.PARCEL_COLORS, "m_w = 1 - w_n / w_dop",
                 "m_a = 1 - a_N / a_Ndop"):  # fmt: skip
        assert name in words


def test_scale_bar_and_belt_direction(recorded):
    """A 0.5 m scale bar labelled in metres, an arrow along +x0 (the belt's motion)."""
    scene, _, _, _, static, _ = recorded
    (x0, y0), (x1, y1) = static["/top/scale_bar"]["strips"][0]
    assert math.hypot(x1 - x0, y1 - y0) == pytest.approx(0.5, abs=1e-6)
    assert static["/top/scale_bar/label"]["labels"] == ["0.5 m"]
    (vx, vy) = static["/top/belt_direction"]["vectors"][0]
    assert vx > 0.0 and vy == 0.0
    (ox, _) = static["/top/belt_direction"]["origins"][0]
    assert scene.belt_x[0] < ox < ox + vx < scene.belt_x[1]


def test_one_timeline_ending_at_the_last_outcome(recorded):
    """sim_time alone (no log_time / log_tick), its last instant the run's last outcome:
    the fence states the recorder keeps after it (at rest) are not logged."""
    _, outcomes, fence_end, rows, _, path = recorded
    assert timelines(path) == {"sim_time"}
    last_outcome = max(t for _, t in outcomes.values())
    end = max(r[-1][0] for r in rows.values())
    assert end == pytest.approx(last_outcome, abs=1e-6)
    assert fence_end > last_outcome + 1.0  # the bag holds later states: they were left out
    # the parcels gone by then are no longer drawn at the end
    assert rows["/top/parcels"][-1][1]["labels"] in (None, [])


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("parcel 7: SORTED at t = 9.035 s: C_s crossed y0 = s", (7, "sorted")),
        ("parcel 3: NOT_DIVERTED at t = 14.310 s: passed the line end", (3, "passed")),
        ("parcel 12: MISSED at t = 20.000 s: left the belt", (12, "missed")),
        ("parcel 5: SOLVER_FAILURE at t = 1.000 s: no solution", (5, "failed")),
        ("parcel 5: NO_FEASIBLE_COMMAND at t = 1.000 s", (5, "failed")),
        ("run stopped", None),
    ],
    ids=["sorted", "passed", "missed", "solver-failure", "no-command", "other"],
)
def test_the_live_outcome_lines_map_onto_the_four_outcomes(text, expected):
    assert keys.outcome_of_line(text) == expected
