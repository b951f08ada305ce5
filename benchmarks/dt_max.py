"""The adaptive scheme's step cap dt_max on a stiff scene: time, steps and peak-force error.

``python -m benchmarks.dt_max`` solves the scene's default with ``solver.dt_max`` replaced by
each value of ``--dt-max``, timed interleaved (one solve of each value per round, ``--rounds``
rounds, the median of each) and its peak contact force compared with the committed reference
(docs/reports/accuracy/reference/<scene>.npz). The figures go, with the command line and
commit, to docs/reports/dt_max.json and are rendered into the marked section "dt_max on the
stiff scenes" of docs/design/numerics.md; ``--from-json`` renders a committed JSON again.
"""

from __future__ import annotations

import argparse
import shlex
import statistics
import sys
import time
from dataclasses import replace

from benchmarks import REPO
from benchmarks.convergence import reference_peak
from benchmarks.sections import SectionReport, framed
from fence_sorter.physics.params import ParameterError
from fence_sorter.physics.simulate import simulate
from fence_sorter.physics.stepper import collector_off
from fence_sorter.scene import available_scenes, load_scene
from fence_sorter.verification.machine import git_revision, load_average
from fence_sorter.verification.report import table

JSON = REPO / "docs" / "reports" / "dt_max.json"
DOC = REPO / "docs" / "design" / "numerics.md"
BEGIN, END = "<!-- dt-max:begin -->", "<!-- dt-max:end -->"
DT_MAX_MS = (5.0, 6.0, 7.0, 7.5, 8.0, 9.0, 10.0)


def scenarios(scene: str, dt_max_ms: list[float]) -> list:
    """The scene's scenario with each dt_max [ms] (ParameterError naming solver.dt_max)."""
    base = load_scene(scene).scenario
    out = []
    for ms in dt_max_ms:
        solver = replace(base.solver, dt_max=1e-3 * ms)
        solver.validate()
        out.append(replace(base, solver=solver, record=()))
    return out


def measure(scene: str, dt_max_ms: list[float], rounds: int) -> list[dict]:
    """Per dt_max: median wall [s], steps, rejected steps and the peak-force error."""
    scs = scenarios(scene, dt_max_ms)
    ref = reference_peak(scene)
    results = [simulate(sc) for sc in scs]  # warm-up: the kernel loads or compiles
    walls: list[list[float]] = [[] for _ in scs]
    for _ in range(rounds):
        for k, sc in enumerate(scs):
            with collector_off():  # docs/design/numerics.md's timing protocol
                t0 = time.perf_counter()
                simulate(sc)
                walls[k].append(time.perf_counter() - t0)
    rows = []
    for ms, r, w in zip(dt_max_ms, results, walls, strict=True):
        if r.diagnosis is not None:
            raise RuntimeError(f"{scene} at dt_max {ms:g} ms: {r.diagnosis}")
        rows.append(
            {
                "dt_max_ms": ms,
                "wall": statistics.median(w),
                "steps": r.steps,
                "rejected": r.rejected_steps,
                "error": abs(r.peak_contact_force - ref) / ref,
            }
        )
    return rows


def render(data: dict) -> str:
    """The marked section of docs/design/numerics.md, from the JSON alone."""
    rows = data["rows"]
    body = [
        f"{data['scene']}, median of {data['rounds']} interleaved solves per value, measured at "
        f"{data['commit']} by `{data['command']}` (load average {data['load_average']} at the "
        "start, on 2 cores shared with other work):",
        "",
        *table(
            ["dt_max [ms]", *(f"{r['dt_max_ms']:g}" for r in rows)],
            [
                ["ms per event", *(f"{1e3 * r['wall']:.2f}" for r in rows)],
                ["steps / rejected", *(f"{r['steps']}/{r['rejected']}" for r in rows)],
                ["peak-N error", *(f"{r['error']:.2e}" for r in rows)],
            ],
        ),
    ]
    return framed(BEGIN, END, "docs/reports/dt_max.json", data["command"], body)


REPORT = SectionReport("dt_max", JSON, DOC, BEGIN, END, render)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.dt_max",
        description="Time, steps and peak-force error of the adaptive default over dt_max.",
    )
    ap.add_argument("--scene", default="positioned_stiff", help="bench scene (%(default)s)")
    ap.add_argument("--dt-max", nargs="+", type=float, default=list(DT_MAX_MS), help="values [ms]")
    ap.add_argument("--rounds", type=int, default=11, help="interleaved rounds (median)")
    REPORT.add_arguments(ap)
    args = ap.parse_args(argv)
    section = REPORT.rendered_again(ap, args)
    if section is not None:
        return REPORT.write(section, None, args)
    if args.scene not in available_scenes():
        ap.error(f"--scene: unknown scene {args.scene!r}; one of {', '.join(available_scenes())}")
    if args.rounds < 1:
        ap.error(f"--rounds must be >= 1, got {args.rounds}")
    try:
        scenarios(args.scene, args.dt_max)
    except ParameterError as exc:
        ap.error(f"--dt-max: {exc}")
    try:
        reference_peak(args.scene)
    except OSError as exc:
        ap.error(f"--scene: no committed reference for {args.scene} ({exc})")
    command = "python -m benchmarks.dt_max " + shlex.join(sys.argv[1:] if argv is None else argv)
    data = {
        "command": command.rstrip(),
        "commit": git_revision(REPO),
        "load_average": load_average(),
        "scene": args.scene,
        "rounds": args.rounds,
    }
    data["rows"] = measure(args.scene, args.dt_max, args.rounds)
    return REPORT.write(render(data), data, args)


if __name__ == "__main__":
    sys.exit(main())
