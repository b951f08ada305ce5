"""Work-precision diagrams: error against wall time for every integration method.

For each benchmark scene and each method over a range of step sizes (fixed-step methods) or
tolerances (adaptive and the SciPy baselines), one solve is compared with a reference solution of
the same scene and timed. The result is a table per scene and log-log plots of error against wall
time, one curve per method, with the scene's default configuration as a marked point.

Reference. Our ``trapezoidal`` at a fixed step of 2 ms / 512 (``REF_DT``), its contact iteration
converged to 1e-12 (``REF_TOLERANCE``; the default 1e-9 would floor it): second order with the
model's discontinuities located, it reaches a converged solution at a bounded cost (no error
estimator to trust, no tolerance-to-error mapping). It is checked three ways, each reported:

- its halved-step twin (same scheme at ``REF_DT / 2``): the difference estimates the reference's
  own error (for a second-order scheme the reference error is about 4/3 of it);
- ``generalized_alpha`` at ``REF_DT``: an independent time discretisation of the same model;
- a SciPy solver at a tight tolerance (``ODE_REFERENCE``) on the ODE form of the model
  (``kernel.rhs``, explicit Karnopp friction): the converged answer of the SciPy baselines. Where
  it differs from the reference by more than the reference's own error, the two forms of the
  model differ, and no SciPy run can be more accurate than that difference; the plots draw it as
  the SciPy floor and the tables add each SciPy run's peak-force error against it.

Error measures (``error_measures``), each against the reference:

- ``peak_force``: |N_peak - N_ref| / N_ref, N_peak the run's largest summed fence normal force
  over its accepted points;
- ``trajectory``: RMS over a 1 ms grid on the common time span of the distance between the run's
  and the reference's C_s, both interpolated by cubic Hermite splines through the accepted
  points' positions and velocities;
- ``trajectory_to_sort``: the same up to the reference's sort crossing, for a scene that runs on
  after it (there the load leaves the belt, and the rest of the run carries the velocity error
  made at that switch);
- ``tip_deflection``: RMS on the same grid of the fence tip deflection difference (linear
  interpolation between accepted points); flexible fences only;
- ``final_pose``: the largest displacement of a load corner between the run's and the
  reference's pose (x, y, phi) at the common end time (the sort crossing, give or take a step,
  for a scene that stops when sorted).

Timing: one untimed warm-up solve per scene and method (the Numba kernel compiles or loads on
first use), then the median of ``repeats`` ``time.perf_counter()`` wall times of ``simulate()``
(one for a solve longer than ``LONG_RUN`` s). A solve stopped by ``solver.max_wall_time`` is
reported as capped, with no error point, and the method's tighter settings are skipped.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from fence_sorter.verification.accuracy_report import (
    render_readme,
    replot,
    rerender,
    scene_data,
    summary,
    write_report,
)
from fence_sorter.verification.accuracy_runs import (
    MEASURES,
    METHODS,
    QUICK_METHODS,
    QUICK_SCENES,
    RECORD,
    SCENES,
    WARMUP_WALL,
    Campaign,
    Progress,
    Reference,
    ReferenceSolution,
    RunPoint,
    SceneResult,
    Trace,
    _load,
    _quiet,
    configure,
    describe,
    error_measures,
    grid,
    machine_info,
    measure,
    reference,
    setting_name,
    timed,
)


def run_campaign(
    scenes: Sequence[str] | None = None,
    methods: Sequence[str] | None = None,
    out_dir: Path | str | None = None,
    repeats: int = 3,
    quick: bool = False,
    *,
    max_wall: float = 30.0,
    command: str = "",
    progress: Progress = _quiet,
) -> Campaign:
    """Run the work-precision campaign; write the report into ``out_dir`` if given."""
    scenes = tuple(scenes or (QUICK_SCENES if quick else SCENES))
    methods = tuple(methods or (QUICK_METHODS if quick else METHODS))
    for m in methods:
        grid(m)  # rejects an unknown method before any solve
    t_start = time.perf_counter()
    campaign = Campaign(
        scenes=[],
        methods=methods,
        quick=quick,
        repeats=repeats,
        max_wall=max_wall,
        command=command,
        machine=machine_info(),
        started=time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    )
    for scene in scenes:
        sc0 = _load(scene)
        ref = reference(scene, quick=quick, progress=progress, base=sc0)
        points = []
        default = replace(sc0, record=RECORD, solver=replace(sc0.solver, max_wall_time=max_wall))
        timed(default)  # warm-up
        p = measure(scene, default, ref, repeats, is_default=True)
        progress(_line(p))
        points.append(p)
        for method in methods:
            values = grid(method, quick)
            warm = configure(sc0, method, values[0], min(max_wall, WARMUP_WALL))
            timed(warm)
            capped = None
            for value in values:
                if capped is not None:
                    points.append(
                        RunPoint(
                            scene,
                            method,
                            setting_name(method),
                            value,
                            "skipped",
                            note=f"skipped: {setting_name(method)} = {capped:g} already hit "
                            f"the {max_wall:g} s cap",
                        )
                    )
                    continue
                p = measure(scene, configure(sc0, method, value, max_wall), ref, repeats)
                progress(_line(p))
                points.append(p)
                if p.status == "capped":
                    capped = value
        campaign.scenes.append(SceneResult(scene, ref.main.sim_time, ref, points))
    campaign.duration = time.perf_counter() - t_start
    if out_dir is not None:
        write_report(campaign, out_dir)
    return campaign


def _line(p: RunPoint) -> str:
    err = " ".join(f"{k}={v:.2e}" for k, v in p.errors.items() if math.isfinite(v))
    tag = " (default)" if p.is_default else ""
    return (
        f"{p.scene}: {describe(p.method, p.value)}{tag}: {p.status}, wall {p.wall * 1e3:.1f} ms, "
        f"{p.steps} steps {err} {p.note}"
    ).rstrip()


__all__ = [
    "Campaign",
    "METHODS",
    "MEASURES",
    "Reference",
    "ReferenceSolution",
    "RunPoint",
    "SCENES",
    "Trace",
    "configure",
    "error_measures",
    "grid",
    "reference",
    "render_readme",
    "replot",
    "scene_data",
    "rerender",
    "run_campaign",
    "summary",
    "write_report",
]
