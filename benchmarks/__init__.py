"""The campaigns that regenerate this repository's reports (docs/reports/), beside the package.

Not installed: they measure the twin of this checkout and write into it. Run them from the
checkout (``source scripts/env.sh`` first):

- ``python -m benchmarks bench``: speed and memory of the default configuration against SciPy
  baselines -> docs/reports/benchmarks.md (:mod:`benchmarks.bench`);
- ``python -m benchmarks bench-suite``: the node suite's pacing, lost messages, controller
  latency and unpaced real-time factor -> its section of docs/reports/benchmarks.md
  (:mod:`benchmarks.bench_suite`, with the host stall probe :mod:`benchmarks.stall_probe`);
- ``python -m benchmarks faults``: the fault-injection campaign -> docs/reports/reliability.md
  (:mod:`benchmarks.faults`);
- ``python -m benchmarks calibrate-bench``: interval coverage, identifiability and wall time of
  the calibration -> docs/reports/calibration.md (:mod:`benchmarks.calibrate_bench`);
- ``python -m benchmarks line-bench``: a line's saturation curve -> docs/reports/line-bench.md;
- ``python -m benchmarks line-scale``: the line over DDS against its number of units (speed,
  paced deadline misses, hand-off transit) -> docs/reports/line-scale.md and ``.json``;
- ``python -m benchmarks paper-sweep NAME``: the optimisation sweeps of the paper's Figs. 3-10
  and the controller's decision table -> docs/reports/paper/ (:mod:`benchmarks.paper`);
- ``python -m benchmarks.startup``: a process's start-up, part by part -> docs/reports/startup/;
- ``python -m benchmarks.versus BASE``: the solve's speed against commit BASE ->
  docs/reports/versus.md;
- ``python -m benchmarks.convergence``: the adaptive scheme's convergence with rtol ->
  docs/reports/convergence.json and its section of docs/design/numerics.md;
- ``python -m benchmarks.imports``: the modules and wall time of the command line's ``--help``
  -> docs/reports/imports.json and its section of docs/design/imports.md;
- ``python -m benchmarks.dt_max``: the adaptive step cap on a stiff scene ->
  docs/reports/dt_max.json and its section of docs/design/numerics.md;
- ``python -m benchmarks.simulator_bench``: the simulator node's pacing in one process;
- ``python -m benchmarks.rerun_bench [BAG]``: the cost of Rerun logging per frame.

The package's own verification a user runs on a scene of theirs stays in the package
(``fence-sorter accuracy``, ``fence-sorter stability``).
"""

from pathlib import Path

#: the checkout the campaigns measure and write their reports into
REPO = Path(__file__).resolve().parents[1]
