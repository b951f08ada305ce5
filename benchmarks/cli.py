"""``python -m benchmarks <campaign> ...``: the campaigns that regenerate the reports of docs/.

The same dispatch as ``fence-sorter`` (:class:`fence_sorter.cli.main.CommandLine`): the
campaign ``a-b`` lives in ``benchmarks.commands.a_b``, which exposes ``register(parser)``.
"""

from __future__ import annotations

from collections.abc import Sequence

from fence_sorter.cli import main as fence_sorter_cli

#: campaign -> its one-line help, in the order of ``--help``
CAMPAIGNS = {
    "bench": "speed and memory of the default against compiled peers and SciPy baselines",
    "bench-suite": "node suite benchmark: pacing, lost messages, controller latency, unpaced RTF",
    "faults": "fault-injection campaign of the node suite (writes docs/reports/reliability.md)",
    "calibrate-bench": "calibration benchmark: interval coverage, identifiability, wall time",
    "paper-sweep": "the optimisation sweeps of the paper's Figs. 3-10 and the decision table",
    "planner-latency": "planner latency against the command deadline; its strokes on the plant",
    "line-bench": "saturation curve of a line: sort rate and throughput against induction rate",
    "line-scale": "the line over DDS against its units: speed, paced misses, hand-off transit",
    "line-speed": "speed of the ROS-free line: sim time / wall time, median of a few runs",
    "limits": "a user's mixed stream over DDS: sorted parcels against the limits (7)-(12)",
    "stability-random": "random stability campaign: events over the user's space, failures",
}
BENCHMARKS = fence_sorter_cli.CommandLine(
    "python -m benchmarks",
    "Campaigns that regenerate this repository's reports (docs/).",
    "benchmarks.commands",
    CAMPAIGNS,
)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the campaign named in ``argv`` (None: the process's arguments); its exit code."""
    return fence_sorter_cli.main(argv, BENCHMARKS)
