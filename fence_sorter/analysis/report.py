"""``analyze_bag``: read a bag, build the table and the summary, write CSV, JSON and plots."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from fence_sorter.analysis.run import TABLE_COLUMNS, load_run, parcel_table, stream_summary
from fence_sorter.capacity.delivered import describe
from fence_sorter.jsonsafe import json_safe
from fence_sorter.recording import topics
from fence_sorter.recording.bagread import BagIssue, read_bag

ANALYSIS_TOPICS = (
    topics.PARCELS, topics.FENCE_COMMANDS, topics.SORT_OUTCOMES, topics.LOAD_STATES,
    topics.FENCE_STATE, topics.MARKERS, topics.DIAGNOSTICS, topics.SORT_EVENTS,
)  # fmt: skip


@dataclass
class AnalysisReport:
    bag: str
    rows: list[dict]
    summary: dict
    issues: list[BagIssue]
    notes: list[str]
    counts: dict[str, int]
    files: dict[str, str] = field(default_factory=dict)  # what was written: name -> path

    def to_json(self) -> dict:
        return json_safe(
            {
                "bag": self.bag,
                "summary": self.summary,
                "parcels": self.rows,
                "issues": [
                    {"file": i.file, "problem": i.problem, "recovered": i.recovered}
                    for i in self.issues
                ],
                "notes": self.notes,
                "message_counts": self.counts,
                "files": self.files,
            }
        )


def analyze_bag(bag: Path | str, out_dir: Path | str | None = None, plots: bool = True):
    """Analyse a bag; with ``out_dir`` write parcels.csv, analysis.json and the plots there.

    Raises:
        BagReadError: nothing readable at the path (not a bag).

    """
    contents = read_bag(bag, topics=ANALYSIS_TOPICS)
    run = load_run(contents)
    rows = parcel_table(run)
    report = AnalysisReport(
        str(bag), rows, stream_summary(run, rows), contents.issues, run.notes, contents.counts()
    )
    if out_dir is None:
        return report
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "parcels.csv"
    with csv_path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=TABLE_COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv(row.get(k, "")) for k in TABLE_COLUMNS})
    report.files["parcels.csv"] = str(csv_path)
    if plots:
        from fence_sorter.analysis.plots import (  # lazy: loads Matplotlib, rosbags
            plot_damage_risk,
            plot_impact,
            plot_overview,
            plot_parcel,
        )

        if run.series:
            report.files["trajectories.png"] = str(plot_overview(run, out / "trajectories.png"))
        if report.summary["damage_risk"]["parcels_with_impact"]:
            path = plot_damage_risk(rows, out / "damage_risk.png")
            report.files[path.name] = str(path)
        for pid in sorted(run.events):
            made = plot_impact(run, pid, out / f"impact_{pid}.png")
            if made is not None:
                report.files[made.name] = str(made)
        for pid in sorted(run.series):
            made = plot_parcel(run, pid, out / f"parcel_{pid}.png")
            if made is not None:
                report.files[made.name] = str(made)
    json_path = out / "analysis.json"
    report.files["analysis.json"] = str(json_path)
    json_path.write_text(json.dumps(report.to_json(), indent=1) + "\n", encoding="utf-8")
    return report


def _csv(value):
    if isinstance(value, list):
        return ";".join(str(v) for v in value)
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return value


def missing_parcels(summary: dict) -> list[str]:
    """One line per kind of record the bag has without its parcel's /parcels message."""
    kinds = (("outcomes_without_parcel", "outcome"), ("commands_without_parcel", "command"))
    return [
        f"{what} of parcel(s) {summary[key]} without their /parcels message: the bag lost the "
        "scan; stream figures are incomplete"
        for key, what in kinds
        if summary[key]
    ]


def format_report(report: AnalysisReport) -> str:
    """Human-readable table and summary."""

    def f(v, spec=".3g"):
        if v is None or (isinstance(v, float) and not math.isfinite(v)):
            return "-"
        return f"{v:{spec}}" if isinstance(v, float) else str(v)

    lines = [f"bag {report.bag}: " + ", ".join(f"{k} {v}" for k, v in report.counts.items())]
    head = (
        f"{'id':>4} {'divert':>6} {'sorted':>6} {'reason':<20} {'w_n':>6} {'N':>7} "
        f"{'N_stiff':>7} {'a_N':>6} {'v_exit':>6} {'t_ws':>6} {'m_w':>6} {'m_a':>6} "
        f"{'h':>6}  check"
    )
    lines += [head, "-" * len(head)]
    for r in report.rows:
        check = {True: "ok", False: "DIFFERS: " + r["disagreements"], None: "no live outcome"}
        lines.append(
            f"{r['parcel_id']:>4} {f(r['divert']):>6} {f(r['sorted']):>6} {r['reason']:<20} "
            f"{f(r['impact_speed_mps']):>6} {f(r['peak_N']):>7} {f(r['peak_N_stiff']):>7} "
            f"{f(r['peak_accel_mps2']):>6} {f(r['exit_speed_mps']):>6} "
            f"{f(r['time_in_ws_s']):>6} {f(r['impact_speed_margin'], '+.2f'):>6} "
            f"{f(r['accel_margin'], '+.2f'):>6} {f(r['drop_height_m'], '.3f'):>6}  "
            f"{check[r['agrees']]}"
        )
    s = report.summary
    lines += [
        "units: w_n impact speed [m/s], N, N_stiff peak forces [N], a_N peak acceleration "
        "[m/s^2], v_exit exit speed [m/s], t_ws time in the working space [s] (live figures); "
        "m_w = 1 - w_n/w_dop and m_a = 1 - a_N/a_Ndop the margins against the limits (< 0: "
        "over), h = w_n^2/(2 g) the drop height of the impact [m]",
        f"stream: {s['parcels']} parcels, {s['divert']} to divert, {s['sorted_divert']} sorted "
        f"(share {f(s['share_sorted'], '.0%')}), throughput {f(s['throughput_pcs_h'], '.0f')} "
        f"pcs/h, sorted {f(s['sorted_pcs_h'], '.0f')} pcs/h, planned capacity (min) "
        f"{f(s['planned_capacity_pcs_h_min'], '.0f')} pcs/h",
    ]
    strokes = [r for r in report.rows if "r_s_m" in r]
    if strokes:
        head = (
            f"{'id':>4} {'m':>5} {'A':>5} {'B':>5} {'R_s':>5} {'t1':>5} {'w_n plan/got':>13} "
            f"{'a_N plan/got':>13} {'ydot plan/got':>13}  over"
        )
        lines += ["", head, "-" * len(head)]
        for r in strokes:
            lines.append(
                f"{r['parcel_id']:>4} {f(r['mass_kg'], '.1f'):>5} "
                f"{f(r['length_a_m'], '.2f'):>5} {f(r['width_b_m'], '.2f'):>5} "
                f"{f(r['r_s_m'], '.2f'):>5} {f(r['t1_s'], '.2f'):>5} "
                f"{f(r['planned_impact_speed_mps'], '.2f'):>6}/"
                f"{f(r['delivered_impact_speed_mps'], '.2f'):<6} "
                f"{f(r['planned_accel_mps2'], '.0f'):>6}/{f(r['delivered_accel_mps2'], '.0f'):<6} "
                f"{f(r['planned_exit_speed_mps'], '.2f'):>6}/"
                f"{f(r['delivered_exit_speed_mps'], '.2f'):<6}  "
                + (",".join(f"({c})" for c in r["over_limits"]) or "-")
                + ("  FAILED EVENT" if r["failed"] else "")
            )
        lines.append(
            "m mass [kg], A, B sizes [m], R_s [m], t1 [s]: the stroke; plan/got: the "
            "controller's prediction and what the plant delivered; over: limits a sorted "
            "parcel went over"
        )
    lines.append(f"limits: {describe(s['limits'])}")
    risk = s["damage_risk"]
    if risk["parcels_with_impact"]:
        worst = ", ".join(
            f"{w['parcel_id']} (m_w {w['impact_speed_margin']:+.2f}, m_a "
            f"{w['accel_margin']:+.2f}, h {w['drop_height_m']:.3f} m)"
            for w in risk["worst_parcels"]
        )
        lines.append(
            f"damage risk: {risk['parcels_with_impact']} parcels with an impact, "
            f"{f(risk['share_over_w_dop'], '.0%')} over w_dop "
            f"{risk['parcels_over_w_dop'] or ''}, {f(risk['share_over_a_ndop'], '.0%')} over "
            f"a_Ndop {risk['parcels_over_a_ndop'] or ''}; worst: {worst}"
        )
    if s["sort_events"]:
        lines.append(
            f"full-rate events: {s['sort_events']} /sort_events messages, peaks checked against "
            "the live outcomes (within 0.5 %)"
        )
    agree = s["agrees_with_live"]
    lines.append(
        "recorded states vs live outcomes: "
        + (
            f"agree for all {s['parcels_checked']} parcels"
            if agree
            else (
                "nothing to compare"
                if agree is None
                else f"DIFFER for parcels {s['parcels_disagreeing']}"
            )
        )
        + (
            f"; no live outcome for {s['parcels_without_outcome']}"
            if s["parcels_without_outcome"]
            else ""
        )
    )
    for problem in missing_parcels(s):
        lines.append(f"INCOMPLETE: {problem}")
    for note in report.notes:
        lines.append(f"note: {note}")
    for issue in report.issues:
        lines.append(f"BAG PROBLEM: {issue}")
    for name, path in report.files.items():
        if name.endswith((".csv", ".json")):
            lines.append(f"wrote {path}")
    plots = [n for n in report.files if n.endswith(".png")]
    if plots:
        lines.append(f"wrote {len(plots)} plots: {', '.join(plots)}")
    return "\n".join(lines)
