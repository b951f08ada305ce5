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

from dataclasses import dataclass
from pathlib import Path

from fence_sorter.analysis.line_bag import ResimLinks, line_records, replay
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
