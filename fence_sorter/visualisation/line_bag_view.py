"""The Rerun view of a line's bag (``fence-sorter rrd BAG`` on a bag of ``run --line --bag``).

The line view (:mod:`fence_sorter.visualisation.line_view`: the top view of the whole belt
with every unit and the parcels, per-unit plots) samples the units' simulations (fence
shapes, parcels in a stroke), which do not go on the wire. They are rebuilt from the bag's
records: :class:`~fence_sorter.analysis.line_bag.ResimLinks` feeds each unit's recorded
commands, in their order, to that unit simulated here, while the owner is replayed on the
recorded replies, and each reply the simulated unit makes is compared with the recorded one.
Every unit is deterministic in its commands and hand-offs, so the view shows the run's
units; ``replies_differing`` names the first replies that do not match (none: the view is
the run's).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fence_sorter.analysis.line_bag import LineBagError, ResimLinks, line_records, replay
from fence_sorter.recording.bagread import BagContents
from fence_sorter.visualisation.line_view import LineRerunLogger, line_blueprint, open_recording

#: sim time between the view's samples [s] (line-sim --rrd's default)
PERIOD = 0.02


@dataclass(frozen=True)
class LineBagView:
    samples: int
    replies_checked: int
    replies_differing: tuple[str, ...]
    summary: dict


def log_line_bag(
    bag: BagContents, out: Path, spawn: bool = False, period: float = PERIOD
) -> LineBagView:
    """Write the line view of ``bag`` to ``out`` (.rrd); LineBagError when it is no line's bag
    or misses a reply."""
    records = line_records(bag)
    links = ResimLinks(records)
    rec = open_recording(
        out, spawn=spawn, layout=lambda paused: line_blueprint(records.line, paused)
    )
    logger = LineRerunLogger(rec, records.line, period=period)
    owner = None
    try:
        summary, owner = replay(records, links, observers=(logger.observe,))
    finally:
        logger.close(owner)
    return LineBagView(logger.samples, links.resim_checked, tuple(links.resim_differing), summary)


def write_line_view(
    bag: BagContents,
    out: Path,
    spawn: bool = False,
    *,
    say: Callable[[str], None],
    warn: Callable[[str], None],
) -> int:
    """Write the line view of ``bag`` to ``out``, ``say`` what was written and ``warn`` of
    each problem; the exit status of ``rrd BAG`` and ``run --line --rrd``: 0 the run's view,
    1 a reply of a unit simulated again differs from the recorded one (named), a reply is
    missing or the bag has problems."""
    try:
        view = log_line_bag(bag, out, spawn=spawn)
    except LineBagError as exc:
        warn(str(exc))
        for issue in bag.issues:
            warn(issue)
        return 1
    say(
        f"wrote {out} (the line view: {view.samples} samples; {view.replies_checked} replies "
        f"of the units simulated again, {len(view.replies_differing)} differ from the "
        f"recorded ones; {out.stat().st_size / 1e6:.2f} MB)"
    )
    for issue in bag.issues:
        warn(issue)
    if view.replies_differing:
        warn("replies differ from the recorded ones: " + ", ".join(view.replies_differing))
    return 1 if bag.issues or view.replies_differing else 0
