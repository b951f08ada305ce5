"""Analysis of recorded runs (ROS-free): per-parcel table, stream figures, paper-style plots,
and the check of the recorded states against the outcomes the simulator published live."""

from fence_sorter.analysis.report import AnalysisReport, analyze_bag
from fence_sorter.analysis.run import RecordedRun, load_run, parcel_table, stream_summary

__all__ = [
    "AnalysisReport",
    "RecordedRun",
    "analyze_bag",
    "load_run",
    "parcel_table",
    "stream_summary",
]
