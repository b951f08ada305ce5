"""The fault-injection campaign of the node suite: the faults below, injected again and
counted, written to docs/reports/reliability.md (``python -m benchmarks faults``).

Cases:

- **interrupts**: ``fence-sorter run --parcels 20`` started with setsid (as from a terminal);
  the first SIGINT to its process group at a random moment in [0, 30] s, then 1-4 more at
  random gaps of 0-0.5 s (2-5 in all). Every process the run started is tracked (its
  descendants, polled every 0.1 s); figures: exit status, seconds from the first signal to
  the exit, processes still alive 1 s after the exit, tracebacks.
- **floods**: during ``fence-sorter run --parcels 20 --json``, another process publishes
  5000 messages/s for 2 s on /parcels (another run's plausible parcels with the run's own
  ids) or /fence_commands (forged ``feasible: false`` for them); figures: messages sent,
  taken, refused and lost per node, divert parcels without an outcome, deadline misses.
- **wire**: malformed and hostile parcels and commands published one by one to a controller
  and a simulator of one run; each must be refused and counted under its reason while both
  nodes run on.
- **bad input**: files, scenes, streams and parameters given to the command line; each must
  exit with its status and one line, no traceback.
- **insiders**: forged duplicates, a flood and a second /clock with the run's own id
  (:mod:`benchmarks.insiders`).
- **freezes**: a run whose pacing loop or controller is stopped (SIGSTOP) for 3 s, and one
  recording into a full file system (a small tmpfs); the stop must show in the figures, the
  full disk be reported when it happens (exit status 5).
- **line**: ``fence-sorter run --line two_units`` with its link cut for 2 s between two
  network namespaces, a unit's process killed, a whole host's processes killed
  (:mod:`benchmarks.faults_line`); every parcel must be accounted for.
"""

from __future__ import annotations

import json
import random
import shlex
import sys
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

from benchmarks import insiders
from benchmarks.faults_cli import cli_cases, run_cli_case
from benchmarks.faults_floods import command_msg, flood_main, flood_trial, parcel_msg
from benchmarks.faults_freezes import FREEZE_SPACING, FREEZES, freeze_met, freeze_trial
from benchmarks.faults_interrupts import interrupt_trial
from benchmarks.faults_line import LINE_CASES, line_met, line_sim_reference, line_trial
from benchmarks.faults_report import (
    SECTIONS,
    cli_row,
    flood_row,
    render_report,
    verdicts,
    wire_row,
    write_report,
)
from benchmarks.faults_wire import run_wire
from fence_sorter.runner.processes import (
    run_domain_id,
)
from fence_sorter.verification.machine import git_revision, machine_info


def campaign(
    out: Path,
    trials: int = 20,
    seed: int = 16,
    which: tuple[str, ...] = tuple(SECTIONS),
    rate: float = 5000.0,
    seconds: float = 2.0,
    progress=print,
) -> dict[str, bool]:
    """Run the cases named in ``which``, replace their sections of the report ``out`` (the
    others are kept from its JSON) and return whether each section met its target."""
    rng = random.Random(seed)
    workdir = Path(tempfile.mkdtemp(prefix="fence_sorter_faults_"))
    try:
        data = json.loads(out.with_suffix(".json").read_text())
    except (OSError, ValueError):
        data = {}
    info = machine_info()
    machine = ", ".join(info[k] for k in ("cpu", "cores", "memory"))

    def meta(name: str, wall0: float) -> dict:
        argv = ["nice", "-n", "10", "python", "-m", "benchmarks", "faults", "--cases", name]
        if name == "interrupts":
            argv += ["--trials", str(trials), "--seed", str(seed)]
        return {
            "command": shlex.join(argv),
            "commit": git_revision(),
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "machine": machine,
            "wall_s": time.monotonic() - wall0,
        }

    if "wire" in which:
        wall0 = time.monotonic()
        try:
            wire, extra = run_wire(workdir, run_domain_id(), progress)
        except RuntimeError as exc:  # the nodes did not come up: reported, not a traceback
            wire, extra = [], {"error": str(exc)}
        data["wire"] = {"rows": [wire_row(r) for r in wire], "extra": extra}
        data["wire"]["meta"] = meta("wire", wall0)
    if "cli" in which:
        wall0 = time.monotonic()
        rows = []
        for case in cli_cases():
            r = run_cli_case(case, workdir)
            rows.append(cli_row(r))
            progress(
                f"cli   {case.category:10s} {case.name:40s} exit {r.code} "
                + ("ok" if r.ok else "FAILED")
            )
        data["cli"] = {"rows": rows, "meta": meta("cli", wall0)}
    if "floods" in which:
        wall0 = time.monotonic()
        rows = []
        for topic in ("/parcels", "/fence_commands"):
            f = flood_trial(topic, workdir, rate, seconds)
            rows.append(flood_row(f))
            progress(f"flood {topic}: sent {f.sent}, exit {f.exit_code}, leftovers {f.leftovers}")
        data["floods"] = {"rows": rows, "meta": meta("floods", wall0)}
    if "insiders" in which:
        wall0 = time.monotonic()
        data["insiders"] = insiders.section(workdir, progress)
        data["insiders"]["meta"] = meta("insiders", wall0)
    if "freezes" in which:
        wall0 = time.monotonic()
        rows = [freeze_trial(case, workdir) for case in FREEZES]
        for r in rows:
            progress(f"freeze {r['case']}: exit {r.get('exit_code')}, met {freeze_met(r)}")
        data["freezes"] = {"rows": rows, "meta": meta("freezes", wall0)}
    if "line" in which:
        wall0 = time.monotonic()
        ref = line_sim_reference()
        rows = []
        for case in LINE_CASES:
            r = line_trial(case, workdir)
            r["met"] = line_met(r, ref)
            rows.append(r)
            why = f" ({r['not_run']})" if "not_run" in r else ""
            progress(f"line  {case}: met {r['met']}{why}")
        data["line"] = {"rows": rows, "reference": ref, "meta": meta("line", wall0)}
    if "interrupts" in which:
        wall0 = time.monotonic()
        rows = []
        for i in range(trials):
            t = interrupt_trial(rng, workdir)
            rows.append(asdict(t))
            progress(
                f"ctrl-c {i + 1:2d}: first at {t.first_signal_s:5.2f} s, {t.signals} signals, "
                f"exit {t.exit_code} after {t.exit_after_s:.2f} s, leftovers {t.leftovers} "
                f"{t.leftover_names}"
            )
        data["interrupts"] = {"rows": rows, "meta": meta("interrupts", wall0)}
    write_report(out, data)
    return verdicts({k: v for k, v in data.items() if k in which})


def main(argv: list[str] | None = None) -> int:
    """The flooding child process of the campaign (the campaign itself is ``python -m
    benchmarks faults``)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["flood"]:
        return flood_main(argv[1:])
    print(
        "faults: error: the first argument must be 'flood' (the campaign is "
        "`python -m benchmarks faults`)",
        file=sys.stderr,
    )
    return 2


#: the campaign and, for its command and tests, the names of its parts they use
__all__ = [
    "FREEZE_SPACING",
    "campaign",
    "command_msg",
    "main",
    "parcel_msg",
    "render_report",
]


if __name__ == "__main__":
    raise SystemExit(main())
