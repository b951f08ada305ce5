"""The top view's keys: the outcome colour scheme (a parcel's outline while it is on the belt,
its outcome mark where it was last seen), the damage-margin colour scheme (the damage marks
under the belt), a legend of both, a scale bar and the belt's direction.

The two schemes share no colour: outcomes are blue, grey, purple and black; damage margins
run red, orange, yellow, green (:data:`MARGIN_COLORS` over :data:`MARGIN_RANGE`). Entity
paths (static, in the top view's coordinates ``(x, -y)``): ``top/legend/outcome``,
``top/legend/margin`` (swatches), ``top/legend/labels`` (their text), ``top/scale_bar``
(:data:`SCALE_BAR` long) with ``top/scale_bar/label``, ``top/belt_direction`` (an arrow
along +x0) with its label. Outcome marks: ``top/outcomes`` (and ``world/outcomes`` in 3D).
"""

from __future__ import annotations

import re

import numpy as np

from fence_sorter.visualisation.frames import SceneGeometry

#: a parcel's outline while its outcome is pending: what the scan decided
PARCEL_COLORS = {"to divert": (110, 160, 245), "to pass": (185, 185, 185)}
#: the outcome marks: where a parcel was last seen, in its outcome's colour
OUTCOME_COLORS = {
    "sorted": (25, 75, 200),
    "passed": (120, 120, 120),
    "missed": (150, 60, 200),
    "failed": (15, 15, 15),
}
#: what each outcome stands for (the legend's text)
OUTCOME_TEXT = {
    "sorted": "sorted: into the chute",
    "passed": "passed: to pass, at the belt end",
    "missed": "missed: to divert, at the belt end",
    "failed": "failed: no command, rejected",
}
#: /sort_outcomes reason codes (names) -> outcome
OUTCOME_OF_CODE = {"SORTED": "sorted", "NOT_DIVERTED": "passed", "MISSED": "missed"}
#: damage-risk colours: the margin (1 - value / limit, the smaller of w_n's and a_N's) from
#: MARGIN_COLORS[0] at MARGIN_RANGE[0] (over the limit) to [2] at [1] (far from it)
MARGIN_COLORS = ((220, 40, 40), (240, 200, 40), (60, 180, 75))
MARGIN_RANGE = (-0.25, 0.5)
#: the legend's margin swatches: (margin, text)
MARGIN_KEYS = (
    (0.5, "+0.5 and more: far from the limits"),
    (0.125, "+0.1: near a limit"),
    (0.0, "0: at a limit"),
    (-0.25, "below 0: over a limit"),
)
MARGIN_NOTES = ("m_w = 1 - w_n / w_dop (impact speed)", "m_a = 1 - a_N / a_Ndop (acceleration)")
RING_COLOR = (255, 255, 255)  # the ring round an outcome mark (reads on belt and background)
OUTCOME_RADIUS = 0.06  # [m]
LABEL_COLOR = (25, 25, 25)  # labels are dark points of their own: any background
SCALE_BAR = 0.5  # [m]
SCALE_TICK = 0.05  # half height of the scale bar's end ticks [m]
BELT_ARROW = 0.6  # [m]
#: legend rows: this far apart, the first this far above the chute (or belt) [m]
LEGEND_ROW = 0.2
LEGEND_GAP = 0.3
LEGEND_ROWS = 6  # rows of the taller column
#: a label is centred on its point: its left end is put at x by assuming this width per
#: character [m] (the single unit's top view draws about 113 px per metre, 6 px a character)
CHAR_WIDTH = 0.052
#: the viewer draws a point's label below the point: the label points sit this far above
#: the text's line [m] (13 px at the single unit's scale)
LABEL_DROP = 0.11


def outcome_of(code_name: str) -> str:
    """The outcome (sorted, passed, missed, failed) of a /sort_outcomes reason code name."""
    return OUTCOME_OF_CODE.get(code_name, "failed")


def outcome_of_line(text: str) -> tuple[int, str] | None:
    """(parcel id, outcome) of the simulator's outcome line ``parcel <id>: <CODE> at ...``,
    or None for any other text."""
    head = re.match(r"parcel (\d+): ([A-Z_]+)\b", text)
    return (int(head.group(1)), outcome_of(head.group(2))) if head else None


def margin_color(margin: float) -> tuple[int, int, int]:
    """Colour of a damage margin: MARGIN_COLORS interpolated over MARGIN_RANGE (clamped)."""
    lo, hi = MARGIN_RANGE
    u = min(max((margin - lo) / (hi - lo), 0.0), 1.0) * (len(MARGIN_COLORS) - 1)
    k = min(int(u), len(MARGIN_COLORS) - 2)
    f = u - k
    a, b = MARGIN_COLORS[k], MARGIN_COLORS[k + 1]
    return tuple(int(round(a[j] + f * (b[j] - a[j]))) for j in range(3))


def scene_top(scene: SceneGeometry) -> float:
    """Highest point of belt and chute in the sorter frame, y0 [m]."""
    top = scene.belt_width
    if scene.chute is not None:
        cx, cy, sx, sy = scene.chute
        top = max(top, cy + 0.5 * sy)
    return top


def legend_height() -> float:
    """Room the legend takes above the scene [m]."""
    return LEGEND_GAP + (LEGEND_ROWS + 1) * LEGEND_ROW


def _left(x: float, text: str) -> float:
    """x of a label's point so that its text starts at ``x``."""
    return x + 0.5 * CHAR_WIDTH * len(text)


def _line(y: float) -> float:
    """y of a label's point so that its text is centred on ``y`` (view coordinates)."""
    return y - LABEL_DROP


def log_keys(rr, rec, scene: SceneGeometry, top: str) -> None:
    """The legend (outcome and damage-margin colours), the scale bar and the belt direction."""
    x0, x1 = scene.belt_x
    s = scene.belt_width
    y_row0 = -scene_top(scene) - LEGEND_GAP - LEGEND_ROWS * LEGEND_ROW  # view y, first row
    swatch = 0.06
    at, text = [], []

    def column(x: float, title: str, rows, notes=()) -> list:
        at.append((_left(x, title), _line(y_row0)))
        text.append(title)
        points = []
        for k, (colour, words) in enumerate(rows):
            y = y_row0 + (k + 1) * LEGEND_ROW
            points.append(((x + swatch, y), colour))
            at.append((_left(x + 2.5 * swatch, words), _line(y)))
            text.append(words)
        for k, words in enumerate(notes):
            at.append((_left(x, words), _line(y_row0 + (len(rows) + 1 + k) * LEGEND_ROW)))
            text.append(words)
        return points

    outcome_rows = [(c, f"{k} (outline)") for k, c in PARCEL_COLORS.items()]
    outcome_rows += [(OUTCOME_COLORS[k], OUTCOME_TEXT[k]) for k in OUTCOME_COLORS]
    outcome = column(x0, "parcels: outline; outcome: dot where last seen", outcome_rows)
    x_margin = 0.5 * (x0 + x1) + 0.3
    margin = column(x_margin, "damage marks: margin min(m_w, m_a)",
                    [(margin_color(m), words) for m, words in MARGIN_KEYS],
                    MARGIN_NOTES)  # fmt: skip
    for name, points in (("outcome", outcome), ("margin", margin)):
        rec.log(
            f"{top}/legend/{name}",
            rr.Points2D([p for p, _ in points], colors=[c for _, c in points],
                        radii=0.045, draw_order=8.0),
            static=True,
        )  # fmt: skip
    rec.log(
        f"{top}/legend/labels",
        rr.Points2D(at, labels=text, colors=[LABEL_COLOR], radii=0.0, draw_order=8.0),
        static=True,
    )
    # scale bar and belt direction above the belt, right of the chute
    y = -s - 0.2
    xb = x1 - 0.1 - SCALE_BAR
    rec.log(
        f"{top}/scale_bar",
        rr.LineStrips2D(
            [[(xb, y), (xb + SCALE_BAR, y)],
             [(xb, y - SCALE_TICK), (xb, y + SCALE_TICK)],
             [(xb + SCALE_BAR, y - SCALE_TICK), (xb + SCALE_BAR, y + SCALE_TICK)]],
            colors=[LABEL_COLOR], radii=0.008, draw_order=8.0,
        ),
        static=True,
    )  # fmt: skip
    rec.log(
        f"{top}/scale_bar/label",
        rr.Points2D([(xb + 0.5 * SCALE_BAR, _line(y - 0.14))], labels=[f"{SCALE_BAR:g} m"],
                    colors=[LABEL_COLOR], radii=0.0, draw_order=8.0),
        static=True,
    )  # fmt: skip
    xa = xb - 0.3 - BELT_ARROW
    rec.log(
        f"{top}/belt_direction",
        rr.Arrows2D(origins=[(xa, y)], vectors=[(BELT_ARROW, 0.0)], colors=[LABEL_COLOR],
                    radii=0.012, draw_order=8.0),
        static=True,
    )  # fmt: skip
    rec.log(
        f"{top}/belt_direction/label",
        rr.Points2D([(xa + 0.5 * BELT_ARROW, _line(y - 0.14))], labels=["belt direction"],
                    colors=[LABEL_COLOR], radii=0.0, draw_order=8.0),
        static=True,
    )  # fmt: skip


def log_outcome_marks(rr, rec, top: str, marks: dict) -> None:
    """Every outcome so far: ``marks`` parcel id -> (outcome, x, y, z) [m, sorter frame], a
    dot in the outcome's colour in a white ring (its label, shown on hover: id and outcome),
    in the top view and in 3D (at the current time of ``rec``)."""
    if not marks:
        return
    pos = np.array([m[1:] for m in marks.values()], dtype=float)
    colours = [OUTCOME_COLORS[m[0]] for m in marks.values()]
    xy = pos[:, :2] * (1.0, -1.0)
    labels = [f"{pid}: {m[0]}" for pid, m in marks.items()]
    rec.log(
        f"{top}/outcomes",
        rr.Points2D(xy, colors=colours, radii=OUTCOME_RADIUS, draw_order=9.0, labels=labels,
                    show_labels=False),
    )  # fmt: skip
    rec.log(
        f"{top}/outcomes/ring",
        rr.Points2D(xy, colors=[RING_COLOR], radii=OUTCOME_RADIUS + 0.02, draw_order=8.9),
    )
    rec.log(
        "world/outcomes",
        rr.Points3D(
            pos + (0.0, 0.0, 0.05),
            colors=colours,
            radii=OUTCOME_RADIUS,
            labels=labels,
            show_labels=False,
        ),
    )
