"""The fault campaign's report (see :mod:`benchmarks.faults`): the rows of each case, the
verdicts, docs/reliability.md rendered from the JSON data."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks import insiders
from benchmarks.faults_cli import CliResult
from benchmarks.faults_floods import FloodTrial
from benchmarks.faults_freezes import FULL_DISK, freeze_met
from benchmarks.faults_wire import WIRE_RUN, WireResult


# -- the report -------------------------------------------------------------------------------
def _pct(a: float, b: float) -> str:
    return f"{100.0 * a / b:.3f} %" if b else "n/a"


def _intake(summary: dict, node: str, topic: str) -> dict[str, int]:
    diag = summary.get(node, {})
    return {
        k: int(float(diag.get(f"{topic}.{k}", "0") or 0))
        for k in ("received", "accepted", "foreign", "rate_limited", "lost")
    }


#: what the report keeps of a flood run's summary
FLOOD_SUMMARY_KEYS = (
    "parcel_messages",
    "command_messages",
    "divert_without_outcome",
    "sorted_divert",
    "divert",
    "foreign_parcel_messages",
    "foreign_command_messages",
)


def flood_row(f: FloodTrial) -> dict:
    s = f.summary
    keep = {k: s.get(k) for k in FLOOD_SUMMARY_KEYS}
    for node in ("simulator", "controller"):
        diag = s.get(node, {})
        keep[node] = {
            k: v
            for k, v in diag.items()
            if k in ("cycles", "deadline_misses") or k.startswith(("parcels.", "commands."))
        }
    return {
        "topic": f.topic,
        "sent": f.sent,
        "publish_failed": f.publish_failed,
        "exit_code": f.exit_code,
        "leftovers": f.leftovers,
        "traceback": f.traceback,
        "summary": keep,
    }


def wire_row(r: WireResult) -> dict:
    return {"name": r.case.name, "topic": r.case.topic, "counted": r.counted, "ok": r.ok}


def cli_row(r: CliResult) -> dict:
    argv = r.case.argv
    return {
        "category": r.case.category,
        "name": r.case.name,
        "command": " ".join(argv[:1] + tuple(a for a in argv[1:] if "{dir}" not in a)),
        "code": r.code,
        "traceback": r.traceback,
        "line": r.line,
        "ok": r.ok,
    }


def _meta_lines(meta: dict) -> list[str]:
    return [
        f"Command `{meta['command']}` at commit {meta['commit']}, {meta['date']} "
        f"({meta['machine']}), {meta['wall_s']:.0f} s of wall time.",
        "",
    ]


def _interrupts_md(sec: dict) -> list[str]:
    rows = sec["rows"]
    within = sum(1 for t in rows if t["exit_after_s"] <= 5.0)
    L = [
        "## Repeated Ctrl-C",
        "",
        *_meta_lines(sec["meta"]),
        "`fence-sorter run --parcels 20` started with setsid (its own process group, as "
        "from a terminal); the first SIGINT to its process group at a random moment in "
        "[0, 30] s, then more at random gaps of 0-0.5 s "
        "(2-5 in all; fewer when the run was out before the next). Leftovers: processes the "
        "run started (its descendants, polled every 0.1 s) still alive 1 s after it exited. "
        "Exit status -2: the run ended by the signal's default action (a signal in the "
        "interpreter's start-up, before the run's handler exists). Target: 0 leftovers, every "
        "trial out within 5 s.",
        "",
        f"**{len(rows)} trials: {within} exited within 5 s, "
        f"{sum(t['leftovers'] for t in rows)} leftover processes in all, "
        f"{sum(t['traceback'] for t in rows)} with a traceback.**",
        "",
        "| trial | first signal [s] | signals | exit status | exit after [s] | leftovers "
        "| traceback |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for i, t in enumerate(rows, 1):
        names = f" ({t['leftover_names']})" if t["leftover_names"] else ""
        L.append(
            f"| {i} | {t['first_signal_s']:.2f} | {t['signals']} | {t['exit_code']} | "
            f"{t['exit_after_s']:.2f} | {t['leftovers']}{names} | "
            f"{'yes' if t['traceback'] else 'no'} |"
        )
    return [*L, ""]


def _floods_md(sec: dict) -> list[str]:
    L = [
        "## Floods",
        "",
        *_meta_lines(sec["meta"]),
        "During `fence-sorter run --parcels 20 --json`, 3 s after its nodes are up, another "
        "process publishes on the run's domain for 2 s at 5000 messages/s: another run's "
        "plausible parcels with the run's own ids (1-20) on /parcels, or forged "
        "`feasible: false` commands for them on /fence_commands. Received, taken, foreign, "
        "rate-limited, lost: each node's own counters (`<topic>.*` on /diagnostics; lost is "
        "the middleware's message-lost event). Refused at publish: the flooding publisher's "
        "calls the middleware refused. Targets: 0 real divert parcels without an outcome, "
        "every refused or dropped message counted, deadline misses < 0.5 %.",
        "",
        "| flood on | sent | refused at publish | node | received | taken | foreign "
        "(refused) | rate-limited | lost | not counted | divert parcels without outcome "
        "| sorted / to divert | deadline misses | exit status | leftovers |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- "
        "| --- | --- |",
    ]
    for f in sec["rows"]:
        s = f["summary"]
        topic = "parcels" if f["topic"] == "/parcels" else "commands"
        sim = s.get("simulator", {})
        cycles = float(sim.get("cycles", "0") or 0)
        misses = float(sim.get("deadline_misses", "0") or 0)
        own = s.get("parcel_messages" if topic == "parcels" else "command_messages") or 0
        for node in ["simulator"] + (["controller"] if topic == "parcels" else []):
            c = _intake(s, node, topic)
            uncounted = f["sent"] + own - c["received"] - c["lost"]
            L.append(
                f"| {f['topic']} | {f['sent']} | {f['publish_failed']} | {node} | "
                f"{c['received']} | {c['accepted']} | {c['foreign']} | {c['rate_limited']} | "
                f"{c['lost']} | {uncounted} | {len(s.get('divert_without_outcome') or [])} | "
                f"{s.get('sorted_divert')} / {s.get('divert')} | "
                f"{int(misses)} of {int(cycles)} ({_pct(misses, cycles)}) | {f['exit_code']} | "
                f"{f['leftovers']} |"
            )
    foreign = "; ".join(
        f"{f['topic']}: {f['summary'].get('foreign_parcel_messages')} parcels, "
        f"{f['summary'].get('foreign_command_messages')} commands"
        for f in sec["rows"]
    )
    return [
        *L,
        "",
        "Not counted = sent + the run's own messages on the topic - received - lost, per node "
        "(0: every message reached the node's intake or was counted lost). The flood lands in "
        "the simulator's ROS process; its pacing loop is a process of its own (no ROS), so "
        "the deadline misses above are the loop's under the flood. The run's monitor counted "
        f"the foreign messages apart ({foreign}); exit status 4: foreign traffic seen "
        "(README).",
        "",
    ]


def _wire_md(sec: dict) -> list[str]:
    rows, extra = sec["rows"], sec.get("extra", {})
    L = [
        "## Hostile and malformed messages",
        "",
        *_meta_lines(sec["meta"]),
        f"Published one by one to a controller and a simulator of run {WIRE_RUN}; each must "
        "raise its counter by one on the node(s) named while both run on. The commands' "
        "parcels are scanned 0.3 m upstream of the scan line, inside the simulator's tolerance "
        "and outside the controller's, so no real command races them.",
        "",
        *([f"**Not run: {extra['error']}**", ""] if "error" in extra else []),
        f"**{sum(r['ok'] for r in rows)} of {len(rows)} refused and counted; nodes alive at "
        f"the end: {extra.get('alive')}; exit statuses {extra.get('exit_codes')}; leftover "
        f"processes {extra.get('leftovers')}.**",
        "",
        "| message | topic | counted as | rise | result |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        L.append(
            f"| {r['name']} | /{r['topic']} | {', '.join(r['counted'])} | "
            f"{', '.join(str(v) for v in r['counted'].values())} | "
            f"{'refused, counted' if r['ok'] else 'NOT COUNTED'} |"
        )
    return [*L, ""]


def _cli_md(sec: dict) -> list[str]:
    rows = sec["rows"]
    L = [
        "## Bad input at the command line",
        "",
        *_meta_lines(sec["meta"]),
        "Each must exit with its status (2: bad input) with one line naming what is wrong, no "
        "traceback and no output file.",
        "",
        f"**{sum(r['ok'] for r in rows)} of {len(rows)} as required; tracebacks: "
        f"{sum(r['traceback'] for r in rows)}; silently accepted (exit 0): "
        f"{sum(r['code'] == 0 for r in rows)}.**",
        "",
        "| kind | input | command | exit status | traceback | last line | result |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        line = r["line"].replace("|", "\\|")
        line = line if len(line) <= 140 else line[:137] + "..."
        L.append(
            f"| {r['category']} | {r['name']} | `{r['command']}` | {r['code']} | "
            f"{'yes' if r['traceback'] else 'no'} | {line} | {'ok' if r['ok'] else 'FAILED'} |"
        )
    return [*L, ""]


def _insiders_md(sec: dict) -> list[str]:
    return insiders.insiders_md(sec, _meta_lines(sec["meta"]))


def _freezes_md(sec: dict) -> list[str]:
    L = [
        "## Freezes and a full disk",
        "",
        *_meta_lines(sec["meta"]),
        "`fence-sorter run --json` of 12 parcels scanned 1.5 s apart (every other one to "
        "divert); 4 s after its nodes are up, the pacing loop "
        "(the process `fs-line-worker`) or the controller is stopped with SIGSTOP for 3 s and "
        f"continued; or the run records (`--bag`) into a tmpfs of {FULL_DISK} mounted for "
        "it. Deadline misses count every cycle a stalled loop did not run; the controller's "
        "latency runs from the parcel's reception by the middleware (`latency_*`) and from "
        "its publication by the scanner (`latency_from_send_*`: a process stopped as a whole "
        "receives late, so only this one covers the stop). Targets: the stop or the full disk "
        "in the figures, every divert parcel with an outcome, a full disk reported when it "
        "happens with the sim time where the bag ends, exit status 5 (README), no leftovers.",
        "",
        "| case | exit status | sorted / to divert | outcomes | deadline misses | lateness "
        "max [ms] | controller latency p99 / max [ms] | from send p99 / max [ms] | recording "
        "| result |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sec["rows"]:
        if "not_run" in r:
            L.append(f"| {r['case']} | not run: {r['not_run']} | | | | | | | | FAILED |")
            continue
        sim, c = r["simulator"], r["controller"]
        rec = r["recording_failed"]
        rec_text = (
            f"failed at sim {rec['failed_at_sim_s']:.2f} s, bag complete to "
            f"{rec['bag_ends_sim_s']:.2f} s, {rec['messages_not_written']} not written"
            if rec
            else "-"
        )
        L.append(
            f"| {r['case']} | {r['exit_code']} | {r['sorted_divert']} / {r['divert']} | "
            f"{', '.join(f'{k} {v}' for k, v in sorted((r['by_reason'] or {}).items()))} | "
            f"{sim.get('deadline_misses')} of {sim.get('cycles')} | "
            f"{sim.get('cycle_lateness_max_ms')} | {c.get('latency_p99_ms')} / "
            f"{c.get('latency_max_ms')} | {c.get('latency_from_send_p99_ms')} / "
            f"{c.get('latency_from_send_max_ms')} | {rec_text} | "
            f"{'ok' if freeze_met(r) else 'FAILED'} |"
        )
    return [*L, ""]


def _line_md(sec: dict) -> list[str]:
    ref = sec["reference"]
    L = [
        "## A line's link, unit and host faults",
        "",
        *_meta_lines(sec["meta"]),
        f"`fence-sorter run --line two_units --parcels {ref['parcels_inducted']} --seed 3` "
        "(benchmarks/faults_line.py). Link cut and host kills: the line split over two network "
        "namespaces joined by a veth pair (host A: the owner and unit_1, host B: unit_2); 1 s "
        "after the owner's log says the line runs, A's end of the veth goes down for 2 s "
        "(`ip link set ... down`, then `up`), or every process of host B, or of host A, is "
        "killed (SIGKILL). Unit kill: the line on one host, unit_2's process killed (SIGKILL). "
        "Targets: link cut, both hosts exit 0 and the summary equals `line-sim`'s for the seed; "
        "unit kill, exit 0, every parcel accounted for, unit_2 restarted once, rejoined and "
        "sorting again; "
        "host B killed, A exits 0 with every parcel accounted for and unit_2 down at the end; "
        "host A killed, B exits 3 with one line.",
        "",
        "| case | exit A / B | sim [s] / wall [s] | longest reply wait [s] | sorted / rejected "
        "/ lost with a unit | hand-offs sent / received / lost | unit_2 down | restarts | "
        "result |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sec["rows"]:
        if "not_run" in r:
            L.append(f"| {r['case']} | not run: {r['not_run']} | | | | | | | FAILED |")
            continue
        a, b = r["a"], r.get("b", {})
        s = a["summary"]
        links = s.get("links", {}).values()
        down = s.get("units_down", {}).get("unit_2")
        down_text = (
            f"{down['why']}; passed on {down['handoffs_passed_on']}, lost "
            f"{down['lost_parcels'] or 'none'}, rejoined {down['rejoins']}x"
            + (
                f", its new process sorted {down['sorted_by_last_process']}"
                if down.get("sorted_by_last_process") is not None
                else ""
            )
            if down
            else "-"
        )
        fig = f"{s['sim_time_s']:.1f} / {s['wall_time_s']:.1f}" if "sim_time_s" in s else "-"
        wait = f"{s['reply_wait_max_s']:.2f}" if "reply_wait_max_s" in s else "-"
        counts = (
            f"{s['sorted']} / {s['rejected']} / {s['lost_with_unit']}" if "sorted" in s else "-"
        )
        hand = (
            f"{sum(v['sent'] for v in links)} / {sum(v['received'] for v in links)} / "
            f"{sum(v['lost'] for v in links)}"
            if links
            else "-"
        )
        exits = f"{a['exit_code']} / {b.get('exit_code', '-')}"
        if r["case"] == "owner host kill":
            down_text = b.get("last_line", "").replace("|", "\\|")
        L.append(
            f"| {r['case']} | {exits} | {fig} | {wait} | {counts} | {hand} | {down_text} | "
            f"{s.get('restarts', {}).get('unit_2', '-')} | {'ok' if r['met'] else 'FAILED'} |"
        )
    return [*L, ""]


SECTIONS = {
    "interrupts": _interrupts_md,
    "floods": _floods_md,
    "insiders": _insiders_md,
    "wire": _wire_md,
    "cli": _cli_md,
    "freezes": _freezes_md,
    "line": _line_md,
}


def render_report(data: dict, json_name: str = "reliability.json") -> str:
    """The markdown report of ``data`` (section -> {meta, rows[, extra]}) alone."""
    L = [
        "# Reliability: the fault-injection campaign",
        "",
        "`python -m benchmarks faults` (benchmarks/faults.py) injects the faults below "
        "into the node suite and counts what it refused, dropped and sorted; every figure "
        f"comes from the run named in its section (data: {json_name}).",
        "",
    ]
    for name, render in SECTIONS.items():
        if name in data:
            L += render(data[name])
    n_wire = len(data.get("wire", {}).get("rows", []))
    n_cli = len(data.get("cli", {}).get("rows", []))
    L += [
        f"Bad-input table: {n_wire + n_cli} entries ({n_wire} on the wire, {n_cli} at the "
        "command line).",
        "",
    ]
    return "\n".join(L)


def write_report(path: Path, data: dict) -> None:
    """The report ``path`` (markdown) rendered from ``data``, and the data beside it as JSON
    (a later run of some cases replaces only their sections)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_report(data, path.with_suffix(".json").name))
    path.with_suffix(".json").write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")


def verdicts(data: dict) -> dict[str, bool]:
    """Whether each section met its target."""
    out = {}
    if "wire" in data:
        out["wire"] = bool(data["wire"]["rows"]) and all(r["ok"] for r in data["wire"]["rows"])
    if "cli" in data:
        out["cli"] = all(r["ok"] for r in data["cli"]["rows"])
    if "interrupts" in data:
        out["interrupts"] = all(
            t["leftovers"] == 0 and t["exit_after_s"] <= 5.0 for t in data["interrupts"]["rows"]
        )
    if "insiders" in data:
        out["insiders"] = all(insiders.row_ok(r) for r in data["insiders"]["rows"])
    if "freezes" in data:
        out["freezes"] = all(freeze_met(r) for r in data["freezes"]["rows"])
    if "line" in data:
        out["line"] = all(r["met"] for r in data["line"]["rows"])
    if "floods" in data:
        out["floods"] = all(
            not f["summary"].get("divert_without_outcome") and f["leftovers"] == 0
            for f in data["floods"]["rows"]
        )
    return out
