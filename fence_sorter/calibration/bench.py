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
BEGIN, END = "<!-- calibrate-bench:begin -->", "<!-- calibrate-bench:end -->"


def _run(scene: str, truth: dict, sensors: str, stream: str, count: int, seed: int, names,
         workers=None):  # fmt: skip
    base = load_scene(scene).scenario
    with tempfile.TemporaryDirectory() as d:
        bag = emulate_bag(Path(d) / "bag", with_values(base, truth), load_sensors(sensors),
                          scene_name=scene, stream=stream, count=count, seed=seed,
                          workers=workers)  # fmt: skip
        return calibrate(base, read_measured_bag(bag), names, workers=workers)


def coverage(seeds: int, parcels: int, workers=None, log=print) -> dict:
    names = list(TRUTH)
    rows = []
    for seed in range(seeds):
        res = _run(SCENE, TRUTH, "camera60", "default", parcels, 100 + seed, names, workers)
        row = {"seed": 100 + seed, "wall_time_s": res.wall_time}
        for e in res.estimates:
            inside = e.ci95 is not None and e.ci95[0] <= TRUTH[e.name] <= e.ci95[1]
            row[e.name] = {"value": e.value, "ci95": e.ci95, "inside": inside,
                           "verdict": e.verdict}  # fmt: skip
        rows.append(row)
        log(f"seed {100 + seed}: " + ", ".join(
            f"{n} {'in' if row[n]['inside'] else 'OUT'}" for n in names
        ) + f" ({res.wall_time:.0f} s)")  # fmt: skip
    share = {n: sum(r[n]["inside"] for r in rows) / len(rows) for n in names}
    rel = {
        n: sorted((r[n]["ci95"][1] - r[n]["ci95"][0]) / (2 * TRUTH[n]) for r in rows
                  if r[n]["ci95"])[len(rows) // 2]
        for n in names
    }  # fmt: skip
    return {"seeds": seeds, "parcels": parcels, "share_inside": share,
            "median_rel_halfwidth": rel, "rows": rows}  # fmt: skip


def flag_case(workers=None) -> dict:
    want = {"mu_fence": 0.40, "k_p": 2.4e9, "b_p": 4.0e5}
    res = _run("arbitrary_stiff", want, "camera25", "border", 4, 5, list(want), workers)
    return {e.name: {"value": e.value, "ci95": e.ci95, "verdict": e.verdict, "why": e.why}
            for e in res.estimates}  # fmt: skip


def timing(parcels: int, workers=None) -> dict:
    t0 = time.perf_counter()
    res = _run(SCENE, TRUTH, "camera60", "default", parcels, 7, list(TRUTH), workers)
    return {"parcels": parcels, "wall_time_s": res.wall_time, "replays": res.replays,
            "function_evaluations": res.nfev, "with_emulation_s": time.perf_counter() - t0,
            "load_average": os.getloadavg()[0], "cpus": os.cpu_count()}  # fmt: skip


def render(report: dict, command: str, commit: str) -> str:
    lines = [BEGIN, "", f"Measured by `{command}` at {commit} ({platform.machine()}, "
             f"{os.cpu_count()} CPUs).", ""]  # fmt: skip
    cov = report.get("coverage")
    if cov:
        lines += [
            f"**Coverage** ({cov['seeds']} seeds, {cov['parcels']} parcels each, `{SCENE}` "
            "truth " + ", ".join(f"{k} = {v:g}" for k, v in TRUTH.items()) + ", `camera60`; "
            "prior: the plain scene):", "",
            "| parameter | truth inside the 95 % interval | median relative half-width |",
            "| --- | --- | --- |",
        ]  # fmt: skip
        for n in TRUTH:
            s = cov["share_inside"][n]
            lines.append(f"| {n} | {s * 100:.0f} % ({round(s * cov['seeds'])} of {cov['seeds']}) "
                         f"| {cov['median_rel_halfwidth'][n] * 100:.2g} % |")  # fmt: skip
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
        lines += [f"**Wall time**: {tm['parcels']} parcels, 5 parameters: "
                  f"{tm['wall_time_s']:.1f} s for the calibration ({tm['replays']} replays, "
                  f"{tm['function_evaluations']} residual evaluations), "
                  f"{tm['with_emulation_s']:.1f} s with the emulation; load average "
                  f"{tm['load_average']:.1f} on {tm['cpus']} CPUs at the start.", ""]  # fmt: skip
    lines.append(END)
    return "\n".join(lines)


def write_doc(path: Path, section: str) -> None:
    text = path.read_text(encoding="utf-8")
    a, b = text.index(BEGIN), text.index(END) + len(END)
    path.write_text(text[:a] + section + text[b:], encoding="utf-8")
