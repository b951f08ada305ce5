"""Convergence of the adaptive scheme with rtol: peak-force error against the committed references.

Each bench scene is solved by its default method (``adaptive``) with ``solver.rtol`` replaced
(atol = 1e-2 rtol, as ``accuracy.configure`` sets it) and its peak contact force compared with
the one of docs/reports/accuracy/reference/<scene>.npz (``fence-sorter accuracy`` writes them).
``python -m benchmarks.convergence`` writes the figures, with its command line and commit, to
docs/reports/convergence.json and renders them into the marked section of
docs/design/numerics.md ("Convergence of the adaptive scheme with rtol"); ``--from-json`` renders
a committed JSON again without measuring. test/campaigns/test_convergence.py asserts the target,
test/campaigns/test_reports.py that the committed section is the committed JSON rendered.
"""

from __future__ import annotations

import argparse
import shlex
import statistics
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from benchmarks import REPO
from benchmarks.sections import SectionReport, framed
from fence_sorter.physics.params import ParameterError, SolverParams
from fence_sorter.physics.simulate import simulate
from fence_sorter.physics.stepper import collector_off
from fence_sorter.scene import load_scene
from fence_sorter.verification.accuracy_runs import ATOL_PER_RTOL, SCENES
from fence_sorter.verification.machine import git_revision, load_average

REFERENCE_DIR = REPO / "docs" / "reports" / "accuracy" / "reference"
JSON = REPO / "docs" / "reports" / "convergence.json"
DOC = REPO / "docs" / "design" / "numerics.md"
#: the section of DOC the renderer rewrites
BEGIN, END = "<!-- convergence:begin -->", "<!-- convergence:end -->"
RTOLS = (1e-4, 1e-5, 1e-6, 1e-7)
GAIN = 100.0  # the error at the tightest rtol at least this much below the loosest's
MONOTONE = 2.0  # ... and no error more than this above the one of the looser rtol before it
COST_GROWTH = 4.0  # the steps grow with each decade of rtol, by less than this factor


@dataclass
class ConvergencePoint:
    """One solve of a scene at one rtol."""

    scene: str
    rtol: float
    error: float  # |N_peak - N_ref| / N_ref
    steps: int
    rejected: int
    wall: float  # median wall time of simulate() [s]


def reference_peak(scene: str, directory: Path = REFERENCE_DIR) -> float:
    """The peak contact force [N] of the scene's committed reference solution."""
    with np.load(directory / f"{scene}.npz") as data:
        return float(data["peak_contact_force"])


def solve_at(scene: str, rtol: float, repeats: int = 1, ref_peak: float | None = None):
    """The scene's default solved at ``rtol``: its :class:`ConvergencePoint`."""
    sc = load_scene(scene).scenario
    sv = replace(sc.solver, rtol=rtol, atol=rtol * ATOL_PER_RTOL)
    sv.validate()
    sc = replace(sc, solver=sv, record=())
    walls = []
    for _ in range(max(1, repeats)):
        with collector_off():  # docs/design/numerics.md's timing protocol
            t0 = time.perf_counter()
            result = simulate(sc)
            walls.append(time.perf_counter() - t0)
    if result.diagnosis is not None:
        raise RuntimeError(f"{scene} at rtol {rtol:g}: {result.diagnosis}")
    ref = reference_peak(scene) if ref_peak is None else ref_peak
    return ConvergencePoint(
        scene,
        rtol,
        abs(result.peak_contact_force - ref) / ref,
        result.steps,
        result.rejected_steps,
        statistics.median(walls),
    )


def converges(errors: list[float], resolution: float = 0.0) -> tuple[bool, bool]:
    """(gain, monotone) of errors over tightening rtols: the last at least GAIN below the first
    (or at the reference's ``resolution``), and none above MONOTONE times the one before."""
    gain = errors[-1] <= max(errors[0] / GAIN, resolution)
    floor = max(resolution, 1e-300)
    monotone = all(
        max(b, floor) <= MONOTONE * max(a, floor) for a, b in zip(errors, errors[1:], strict=False)
    )
    return gain, monotone


def smooth_cost(steps: list[int]) -> bool:
    """The steps over tightening rtols (a decade apart) grow, each by less than COST_GROWTH."""
    return all(a < b < COST_GROWTH * a for a, b in zip(steps, steps[1:], strict=False))


def table(points: list[ConvergencePoint], rtols=RTOLS) -> list[str]:
    """Markdown rows: per scene, error / steps / wall ms at each rtol."""
    head = "| scene | " + " | ".join(f"rtol {r:.0e}" for r in rtols) + " | gain |"
    lines = [head, "|---|" + "---|" * (len(rtols) + 1)]
    for scene in dict.fromkeys(p.scene for p in points):
        row = {p.rtol: p for p in points if p.scene == scene}
        cells = [
            f"{row[r].error:.1e} / {row[r].steps} / {1e3 * row[r].wall:.2f}" if r in row else ""
            for r in rtols
        ]
        gain = ""
        if rtols[0] in row and rtols[-1] in row and row[rtols[-1]].error > 0:
            gain = f"{row[rtols[0]].error / row[rtols[-1]].error:.0f}x"
        lines.append(f"| {scene} | " + " | ".join(cells) + f" | {gain} |")
    return lines


def points_of(data: dict) -> list[ConvergencePoint]:
    """The points of a convergence JSON (as :func:`report` writes it)."""
    return [ConvergencePoint(**p) for p in data["points"]]


def report(points: list[ConvergencePoint], rtols, repeats: int, command: str) -> dict:
    """The JSON of a measurement: the points with the command line, commit and load."""
    return {
        "command": command,
        "commit": git_revision(REPO),
        "load_average": load_average(),
        "repeats": repeats,
        "atol_per_rtol": ATOL_PER_RTOL,
        "rtols": list(rtols),
        "points": [asdict(p) for p in points],
    }


def render(data: dict) -> str:
    """The marked section of docs/design/numerics.md, from the JSON alone."""
    body = [
        f"Error / steps / median wall ms of {data['repeats']} solves per cell "
        f"(atol = {data['atol_per_rtol']:g} rtol), measured at {data['commit']} by "
        f"`{data['command']}` (load average {data['load_average']} at the start, on 2 cores "
        "shared with other work: the milliseconds are only indicative, a solve longer than a "
        "few ms is preempted):",
        "",
        *table(points_of(data), tuple(data["rtols"])),
    ]
    return framed(BEGIN, END, "docs/reports/convergence.json", data["command"], body)


REPORT = SectionReport("convergence", JSON, DOC, BEGIN, END, render)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.convergence",
        description="Peak-force error of the adaptive default against the committed "
        "references over rtol (error / steps / wall ms per cell).",
    )
    ap.add_argument("--scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--rtols", nargs="*", type=float, default=list(RTOLS))
    ap.add_argument("--repeats", type=int, default=3, help="timed solves per point (median)")
    REPORT.add_arguments(ap)
    args = ap.parse_args(argv)
    section = REPORT.rendered_again(ap, args)
    if section is not None:
        return REPORT.write(section, None, args)
    for scene in args.scenes:
        if scene not in SCENES:
            ap.error(f"--scenes: unknown scene {scene!r}; one of {', '.join(SCENES)}")
    if not args.scenes or not args.rtols:
        ap.error("--scenes and --rtols need at least one value each")
    for rtol in args.rtols:
        try:  # solver.rtol's own range check
            SolverParams(rtol=rtol, atol=rtol * ATOL_PER_RTOL).validate()
        except ParameterError as exc:
            ap.error(f"--rtols: {exc}")
    if args.repeats < 1:
        ap.error(f"--repeats must be >= 1, got {args.repeats}")
    points = []
    for scene in args.scenes:
        ref = reference_peak(scene)
        solve_at(scene, args.rtols[0], 1, ref)  # warm-up (the kernel loads or compiles)
        for rtol in args.rtols:
            p = solve_at(scene, rtol, args.repeats, ref)
            print(
                f"{scene} rtol {rtol:.0e}: error {p.error:.2e}, {p.steps} steps, "
                f"{p.rejected} rejected, {1e3 * p.wall:.3f} ms",
                file=sys.stderr,
                flush=True,
            )
            points.append(p)
    command = "python -m benchmarks.convergence " + shlex.join(
        sys.argv[1:] if argv is None else argv
    )
    data = report(points, args.rtols, args.repeats, command.rstrip())
    return REPORT.write(render(data), data, args)


if __name__ == "__main__":
    sys.exit(main())
