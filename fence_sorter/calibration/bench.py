"""The calibration's benchmark: interval coverage over seeds, identifiability, wall time.

- **coverage**: for each seed an emulated bag (the TRUTH values on ``impact_flexible``,
  ``camera60`` sensors, ``parcels`` parcels of the default stream) is calibrated from the plain
  scene; per parameter, the share of seeds whose 95 % interval holds the truth (target
  85-99 %).
- **flag**: 25 Hz poses of parcels lying at the border (``border`` stream, ``arbitrary_stiff``):
  the contact damping b_p is flagged, not estimated.
- **timing**: one bag of ``timing_parcels`` parcels, five parameters, wall time.

:func:`render` fills the generated section of docs/calibration.md.
"""

from __future__ import annotations

import math
import os
import platform
import tempfile
import time
from pathlib import Path

from fence_sorter.scene import load_scene

from .bag import read_measured_bag
from .emulate import emulate_bag
from .fit import calibrate
from .replay import with_values
from .sensors import load_sensors

SCENE = "impact_flexible"
TRUTH = {
    "mu_belt": 0.55,
    "mu_fence": 0.40,
    "k_p": 2.4e9,
    "b_p": 4.0e5,
    "fence.damping_ratio": 0.08,
}
ISSUE_SEEDS = 20  # the issue's target counts the first 20 seeds
BEGIN, END = "<!-- calibrate-bench:begin -->", "<!-- calibrate-bench:end -->"


def _run(scene: str, truth: dict, sensors: str, stream: str, count: int, seed: int, names,
         workers=None, scheduler="processes"):  # fmt: skip
    base = load_scene(scene).scenario
    with tempfile.TemporaryDirectory() as d:
        bag = emulate_bag(Path(d) / "bag", with_values(base, truth), load_sensors(sensors),
                          scene_name=scene, stream=stream, count=count, seed=seed,
                          workers=workers)  # fmt: skip
        return calibrate(base, read_measured_bag(bag), names, workers=workers,
                         scheduler=scheduler)  # fmt: skip


def coverage(seeds: int, parcels: int, workers=None, scheduler="processes", log=print) -> dict:
    """Per parameter over the seeds: the share whose 95 % interval holds the truth (also over
    the first ``ISSUE_SEEDS``), the RMS of z = log(estimate / truth) / sd (1 for intervals of
    the right width; a 95 % count over n seeds scatters by sqrt(0.05 0.95 / n), z's RMS by
    about 1 / sqrt(2 n)) and the median relative half-width."""
    names = list(TRUTH)
    rows = []
    for seed in range(seeds):
        res = _run(SCENE, TRUTH, "camera60", "default", parcels, 100 + seed, names, workers,
                   scheduler)  # fmt: skip
        row = {"seed": 100 + seed, "wall_time_s": res.wall_time, "cpu_time_s": res.cpu_time}
        for e in res.estimates:
            inside = e.ci95 is not None and e.ci95[0] <= TRUTH[e.name] <= e.ci95[1]
            z = math.log(e.value / TRUTH[e.name]) / e.log_sd if e.value and e.log_sd else None
            row[e.name] = {"value": e.value, "ci95": e.ci95, "inside": inside, "z": z,
                           "verdict": e.verdict}  # fmt: skip
        rows.append(row)
        log(f"seed {100 + seed}: " + ", ".join(
            f"{n} {'in' if row[n]['inside'] else 'OUT'}" for n in names
        ) + f" ({res.wall_time:.0f} s, {res.cpu_time:.0f} CPU s)")  # fmt: skip
    first = rows[:ISSUE_SEEDS]
    share = {n: sum(r[n]["inside"] for r in rows) / len(rows) for n in names}
    share_first = {n: sum(r[n]["inside"] for r in first) / len(first) for n in names}
    rms_z = {
        n: math.sqrt(sum(r[n]["z"] ** 2 for r in rows if r[n]["z"] is not None)
                     / max(1, sum(r[n]["z"] is not None for r in rows)))
        for n in names
    }  # fmt: skip
    rel = {
        n: sorted((r[n]["ci95"][1] - r[n]["ci95"][0]) / (2 * TRUTH[n]) for r in rows
                  if r[n]["ci95"])[len(rows) // 2]
        for n in names
    }  # fmt: skip
    return {"seeds": seeds, "parcels": parcels, "share_inside": share,
            "share_inside_first": share_first, "rms_z": rms_z,
            "median_rel_halfwidth": rel, "rows": rows}  # fmt: skip


def flag_case(workers=None, scheduler="processes") -> dict:
    want = {"mu_fence": 0.40, "k_p": 2.4e9, "b_p": 4.0e5}
    res = _run("arbitrary_stiff", want, "camera25", "border", 4, 5, list(want), workers,
               scheduler)  # fmt: skip
    return {e.name: {"value": e.value, "ci95": e.ci95, "verdict": e.verdict, "why": e.why}
            for e in res.estimates}  # fmt: skip


def timing(parcels: int, workers=None, scheduler="processes") -> dict:
    """One ``parcels``-parcel calibration of five parameters: wall time with the load average
    around it, CPU time (load-independent) and the wall time it implies on an idle machine:
    the main process's CPU time (serial) plus the workers' divided by their number."""
    t0, load0 = time.perf_counter(), os.getloadavg()[0]
    res = _run(SCENE, TRUTH, "camera60", "default", parcels, 7, list(TRUTH), workers,
               scheduler)  # fmt: skip
    n = max(1, min(workers or os.cpu_count() or 1, parcels))
    main_cpu = res.cpu_time - res.worker_cpu_time
    return {"parcels": parcels, "wall_time_s": res.wall_time, "cpu_time_s": res.cpu_time,
            "idle_estimate_s": main_cpu + res.worker_cpu_time / n, "workers": n,
            "scheduler": scheduler, "replays": res.replays,
            "function_evaluations": res.nfev, "with_emulation_s": time.perf_counter() - t0,
            "load_average": load0, "load_average_end": os.getloadavg()[0],
            "cpus": os.cpu_count()}  # fmt: skip


def render(report: dict, command: str, commit: str) -> str:
    lines = [BEGIN, "", f"Measured by `{command}` at {commit} ({platform.machine()}, "
             f"{os.cpu_count()} CPUs).", ""]  # fmt: skip
    cov = report.get("coverage")
    if cov:
        k = min(ISSUE_SEEDS, cov["seeds"])
        lines += [
            f"**Coverage** ({cov['seeds']} seeds, {cov['parcels']} parcels each, `{SCENE}` "
            "truth " + ", ".join(f"{k} = {v:g}" for k, v in TRUTH.items()) + ", `camera60`; "
            "prior: the plain scene):", "",
            f"| parameter | truth inside the 95 % interval, {cov['seeds']} seeds | "
            f"the first {k} seeds | RMS of z | median relative half-width |",
            "| --- | --- | --- | --- | --- |",
        ]  # fmt: skip
        for n in TRUTH:
            s, s1 = cov["share_inside"][n], cov["share_inside_first"][n]
            lines.append(f"| {n} | {s * 100:.0f} % ({round(s * cov['seeds'])} of {cov['seeds']}) "
                         f"| {s1 * 100:.0f} % ({round(s1 * k)} of {k}) "
                         f"| {cov['rms_z'][n]:.2f} "
                         f"| {cov['median_rel_halfwidth'][n] * 100:.2g} % |")  # fmt: skip
        lines += ["", "z = log(estimate / truth) / sd, sd the standard deviation of "
                  "log(value) the interval is built from: RMS 1 for intervals of the right "
                  "width. Per seed (**bold**: the truth outside the interval, |z| > 1.96; "
                  f"the first {k} rows are the first {k} seeds):", "",
                  "| seed | " + " | ".join(TRUTH) + " |",
                  "| --- |" + " --- |" * len(TRUTH)]  # fmt: skip
        for r in cov["rows"]:
            cells = []
            for n in TRUTH:
                z = r[n]["z"]
                cell = "-" if z is None else f"{z:+.2f}"
                cells.append(cell if r[n]["inside"] else f"**{cell}**")
            lines.append(f"| {r['seed']} | " + " | ".join(cells) + " |")
        lines.append("")
    flag = report.get("flag")
    if flag:
        lines += ["**Identifiability** (`arbitrary_stiff`, `border` stream, 4 parcels, "
                  "`camera25`, fit mu_fence, k_p, b_p):", ""]  # fmt: skip
        for n, e in flag.items():
            if e["value"] is None:
                lines.append(f"- {n}: {e['verdict']} ({e['why']})")
            else:
                lines.append(f"- {n}: {e['value']:.4g}, 95 % [{e['ci95'][0]:.4g}, "
                             f"{e['ci95'][1]:.4g}] ({e['verdict']})")  # fmt: skip
        lines.append("")
    tm = report.get("timing")
    if tm:
        lines += [f"**Time**: {tm['parcels']} parcels, 5 parameters, {tm['workers']} "
                  f"worker processes (scheduler `{tm['scheduler']}`): {tm['wall_time_s']:.1f} s "
                  "wall for the "
                  f"calibration at a load average of {tm['load_average']:.1f} to "
                  f"{tm['load_average_end']:.1f} on {tm['cpus']} CPUs; {tm['cpu_time_s']:.1f} "
                  f"CPU s, which on an idle machine is {tm['idle_estimate_s']:.1f} s wall "
                  f"(the main process's CPU time plus the workers' divided by "
                  f"{tm['workers']}); {tm['replays']} replays, "
                  f"{tm['function_evaluations']} residual evaluations; "
                  f"{tm['with_emulation_s']:.1f} s with the emulation.", ""]  # fmt: skip
    lines.append(END)
    return "\n".join(lines)


def write_doc(path: Path, section: str) -> None:
    text = path.read_text(encoding="utf-8")
    a, b = text.index(BEGIN), text.index(END) + len(END)
    path.write_text(text[:a] + section + text[b:], encoding="utf-8")
