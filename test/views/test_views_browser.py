"""The example run's Rerun recording in Rerun's own web viewer under headless Chromium.

The recording is made from the example bag with the current logging code (``fence-sorter
rrd``); ``fence-sorter views`` serves it on 127.0.0.1 and opens it in Debian's chromium
driven by playwright-core (``test/js/browser/``). The test fails on an error the viewer
reports (console or page), on a view that never settles, and on an empty view: the
screenshots must show, in their own panels, the colours the recording draws with (belt
borders, scan line, chute, fence, every parcel's damage mark in its margin's colour, each
plot's series, the damage-risk chart). Outside requests the viewer makes (web fonts, usage
analytics, release check) are refused in the browser, so nothing leaves the machine.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fence_sorter.visualisation import browser
from fence_sorter.visualisation import rerun_keys as rk
from fence_sorter.visualisation import rerun_log as rl

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "bags" / "example_4_parcels"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        browser.missing_tools() is not None, reason=f"no browser: {browser.missing_tools()}"
    ),
]

#: panels of the default layout at WIDTH x HEIGHT: left (top view / 3D), right (plots)
LEFT = (0, 64, 760, 770)
#: the top view's band of belt, chute and damage marks, below the legend
BELT_BAND = (0, 385, 760, 620)
RIGHT = (775, 64, 1280, 770)
#: the four plots of the time-series tab, top to bottom (x0, y0, x1, y1)
PLOTS = [(775, 64 + k * 177, 1280, 64 + (k + 1) * 177) for k in range(4)]


def margin_colours(bag: Path) -> dict[int, tuple[int, int, int]]:
    """Each parcel's damage-margin colour, from the bag's outcomes (independent of the
    recording: the analysis's closed forms)."""
    from fence_sorter.analysis.events import risk_of
    from fence_sorter.analysis.run import OUTCOME_FIELDS
    from fence_sorter.recording.bagread import read_bag

    out = {}
    for m in read_bag(bag).by_topic("/sort_outcomes"):
        risk = risk_of({n: getattr(m.msg, n, math.nan) for n in OUTCOME_FIELDS})
        margin = min(risk["impact_speed_margin"], risk["accel_margin"])
        if math.isfinite(margin):
            out[int(m.msg.parcel_id)] = rl.margin_color(margin)
    return out


def colour_pixels(png: Path, colour: tuple[int, int, int], box, tol: int = 12) -> int:
    """Pixels of ``png`` within ``tol`` of ``colour`` inside ``box`` = (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = box
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)[y0:y1, x0:x1]
    return int((np.abs(img - np.asarray(colour)).max(axis=-1) <= tol).sum())


#: the damage-risk tab's three plots (w_n, a_N, N): their plot areas below the titles
DAMAGE_PLOTS = [(775, 372, 1280, 475), (775, 514, 1280, 614), (775, 656, 1280, 758)]
#: the damage-risk chart's y-scale labels, and the 3D view's chute label (x0, y0, x1, y1)
RISK_SCALE = (770, 130, 800, 300)
CHUTE_LABEL_3D = (380, 360, 530, 400)
#: the time cursor's colour in the plots (egui's line, 2 px wide)
CURSOR = (93, 92, 92)


def cursor_x(png: Path, box, tol: int = 12) -> float | None:
    """x [px] of the time cursor in the plot ``box`` = (x0, y0, x1, y1): the mean of the
    columns in which at least half the rows are the cursor's colour (None: no cursor)."""
    x0, y0, x1, y1 = box
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)[y0:y1, x0:x1]
    on = (np.abs(img - np.asarray(CURSOR)).max(axis=-1) <= tol).sum(axis=0)
    cols = np.nonzero(on >= 0.5 * (y1 - y0))[0]
    return float(x0 + cols.mean()) if cols.size else None


def fence_sorter(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fence_sorter.cli.main", *args],
        capture_output=True, text=True, timeout=1800,
    )  # fmt: skip


def test_example_recording_renders_in_the_web_viewer(tmp_path):
    """``fence-sorter views`` on the example bag's recording: exit 0 (every view settled, no
    viewer error), five screenshots, and in each the colours its panels draw with."""
    rrd = tmp_path / "example.rrd"
    made = fence_sorter("rrd", str(EXAMPLE), "--out", str(rrd))
    assert made.returncode == 0, made.stderr
    res = fence_sorter("views", str(rrd), "--out", str(tmp_path / "views"), "--mid", "10.3")
    assert res.returncode == 0, res.stdout + res.stderr
    lines = {line.split()[0]: line for line in res.stdout.splitlines()}
    assert sorted(lines) == ["3d", "damage", "default", "end", "mid"]
    for line in lines.values():
        assert "settled True" in line and "viewer errors 0" in line, line
    png = {name: tmp_path / "views" / f"{name}.png" for name in lines}

    def seen(name, colour, box, at_least):
        n = colour_pixels(png[name], colour, box)
        assert n >= at_least, f"{name}: {n} pixels of {colour} in {box}, expected >= {at_least}"

    # the top view as it opens: belt borders, scan line, chute; the damage marks of every
    # parcel with an outcome, each in its margin's colour (the bag's closed forms)
    seen("default", (220, 220, 60), LEFT, 1000)  # belt borders
    seen("default", (255, 60, 60), LEFT, 100)  # scan line
    seen("default", (50, 100, 200), LEFT, 300)  # chute outline
    colours = margin_colours(EXAMPLE)
    assert len(colours) == 3
    for colour in colours.values():  # a mark of radius 0.04 m: 15 to 25 pixels
        seen("damage", colour, LEFT, 8)
    # every plot of the time-series tab draws its series in the colours its title names
    contact, tip, alpha, speed = PLOTS
    # (thin lines: a few pixels each; at 1280 x 800 the example draws 16 N, 26 N_stiff, 10
    # solver-step and 437 sampled tip-deflection, 49 alpha_w and 64 speed pixels)
    seen("default", rl.N_COLOR, contact, 8)
    seen("default", rl.N_STIFF_COLOR, contact, 13)
    seen("default", rl.STEPS_COLOR, tip, 4)
    seen("default", rl.SAMPLED_COLOR, tip, 200)
    seen("default", rl.ALPHA_COLOR, alpha, 25)
    seen("default", rl.DIVERT_COLOR, speed, 32)
    # one instant, one x: the time cursor at the same x position on every time series plot
    # (within 2 px), at the first instant (the plot areas' left edges) and mid-run
    for name in ("default", "mid"):
        xs = [cursor_x(png[name], box) for box in PLOTS]
        assert None not in xs, f"{name}: no time cursor found in a plot: {xs}"
        assert max(xs) - min(xs) <= 2.0, f"{name}: time cursor at x = {xs} px"
    # mid-run: the fence deflected into the belt and a parcel on it
    seen("mid", (230, 80, 30), LEFT, 200)
    # the damage-risk tab: the chart's w_n / w_dop and a_N / a_Ndop marks and its limit line
    seen("damage", rl.N_COLOR, RIGHT, 30)
    seen("damage", rl.N_STIFF_COLOR, RIGHT, 30)
    seen("damage", rl.MARGIN_COLORS[0], RIGHT, 100)
    # its three plots: one instant, one x (their tick labels as narrow as each other's)
    xs = [cursor_x(png["damage"], box) for box in DAMAGE_PLOTS]
    assert None not in xs, f"damage: no time cursor found in a plot: {xs}"
    assert max(xs) - min(xs) <= 2.0, f"damage: time cursor at x = {xs} px"
    # its y scale: the ratios 0, 0.5 and 1 in dark text left of the chart (40 pixels here)
    assert colour_pixels(png["damage"], rl.LABEL_COLOR, RISK_SCALE, tol=30) >= 20
    # the end: the damage marks under the belt, each in its parcel's margin colour
    for colour in colours.values():
        seen("end", colour, LEFT, 8)
    # and every parcel's outcome mark (three sorted, one passed) where it left the belt: at
    # least 20 pixels of its colour more than as the recording opens (the legend's swatches
    # sit above this band; the belt's edges hold a few greys)
    for outcome in ("sorted", "passed"):
        colour = rk.OUTCOME_COLORS[outcome]
        before = colour_pixels(png["default"], colour, BELT_BAND)
        seen("end", colour, BELT_BAND, before + 20)
    # the 3D tab: the belt (lit grey), the chute and the scan line at the belt's start
    seen("3d", (70, 70, 70), LEFT, 5000)
    seen("3d", (121, 140, 203), LEFT, 1000)
    seen("3d", (255, 60, 60), LEFT, 15)
    # the chute's label in dark text (34 pixels here; a label in the chute's translucent blue
    # has none)
    assert colour_pixels(png["3d"], rl.LABEL_COLOR, CHUTE_LABEL_3D, tol=30) >= 15


#: the line's layout at WIDTH x HEIGHT: the belt's band in the top view, the alpha_w plot
LINE_BELT = (85, 247, 1255, 292)
LINE_TOP = (0, 64, 1280, 400)  # the top view
LINE_ALPHA = (0, 430, 1280, 575)


def test_line_recording_renders_in_the_web_viewer(tmp_path):
    """A four-unit line's recording (``line-sim --rrd``) in the web viewer: exit 0, the three
    shots settled without a viewer error; at the busiest sample every parcel on the belt in
    the colour the recording gives it (its destination's), and each unit that made strokes
    in its colour on the alpha_w plot."""
    from rrd_read import read_rrd

    from fence_sorter.visualisation import line_view as lv

    rrd = tmp_path / "line.rrd"
    made = fence_sorter(
        "line-sim", "four_units", "--parcels", "8", "--rate", "3000", "--rrd", str(rrd)
    )
    assert made.returncode == 0, made.stdout + made.stderr
    rows = read_rrd(rrd)
    # the sample with the most parcels on the belt (centre at least 0.15 m inside it)
    width = 0.7
    busiest, on_belt = 0.0, []
    for t, r in rows["/top/parcels"]:
        here = [
            c
            for strip, c in zip(r["strips"], r["colors"], strict=True)
            if 0.15 <= -np.mean(np.array(strip[:4])[:, 1]) <= width - 0.15
        ]
        if len(here) > len(on_belt):
            busiest, on_belt = t, here
    assert on_belt
    res = fence_sorter("views", str(rrd), "--out", str(tmp_path / "views"), "--mid", f"{busiest}")
    assert res.returncode == 0, res.stdout + res.stderr
    lines = {line.split()[0]: line for line in res.stdout.splitlines()}
    assert sorted(lines) == ["default", "end", "mid"]
    for line in lines.values():
        assert "settled True" in line and "viewer errors 0" in line, line
    mid = tmp_path / "views" / "mid.png"
    for rgba in set(on_belt):  # colours come back packed as 0xRRGGBBAA
        colour = ((rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255)
        assert colour in lv.DESTINATION_COLORS
        n = colour_pixels(mid, colour, LINE_BELT)
        assert n >= 20, f"parcel colour {colour}: {n} pixels on the belt"
    stroked = [
        k
        for k, u in enumerate(("unit_1", "unit_2", "unit_3", "unit_4"))
        if max(r["scalars"][0] for _, r in rows[f"/plots/alpha_w/{u}"]) > 0.3
    ]
    assert stroked
    for k in stroked:
        n = colour_pixels(mid, lv.UNIT_COLORS[k], LINE_ALPHA)
        assert n >= 20, f"unit {k + 1}'s colour: {n} pixels on the alpha_w plot"
    # the static scene: belt borders, chutes, fences at rest
    assert colour_pixels(mid, lv.BORDER_COLOR, LINE_TOP) >= 1000
    assert colour_pixels(mid, lv.CHUTE_COLOR, LINE_TOP) >= 200
    assert colour_pixels(mid, lv.FENCE_COLOR, LINE_TOP) >= 100
