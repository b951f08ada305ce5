"""One sorting event: integrate a :class:`~.model.Scenario` in time.

:func:`simulate` integrates the :class:`~.model.SortingModel` of a scenario with
``solver.method``: our schemes (``integrators``: adaptive, trapezoidal, generalized_alpha; the
first two by default in one compiled loop, ``engine``, ``solver.engine = python`` for the Python
one) or a SciPy ``solve_ivp`` baseline on the same right-hand side (``baselines``: scipy:RK45,
...), and reduces the run to a :class:`~.result.SimulationResult` (``result.Observer``).
The model and result types live in ``model`` and ``result``; they are imported here too, where
most callers look for them.
"""

from __future__ import annotations

import time

from .engine import run_compiled, uses_compiled
from .integrators import Integrator
from .model import RECORDABLE, Scenario, SortingModel
from .result import EnergyAudit, Observer, SimulationResult

__all__ = [
    "RECORDABLE",
    "EnergyAudit",
    "Observer",
    "Scenario",
    "SimulationResult",
    "SortingModel",
    "simulate",
]


def simulate(sc: Scenario, model: SortingModel | None = None) -> SimulationResult:
    """Run one sorting event from drive start (t = 0) to sorted or the end time."""
    model = model or SortingModel(sc)
    if sc.solver.method.startswith("scipy:"):
        # scipy.integrate and scipy.optimize take ~0.7 s to import (python -X importtime);
        # only the baselines need them
        from .baselines import run_solve_ivp

        return run_solve_ivp(model)
    if uses_compiled(sc):
        return run_compiled(model)
    wall0 = time.perf_counter()
    obs = Observer(model)
    integ = Integrator(model)
    t, diagnosis, steps, rejected = integ.run(obs)
    return obs.result(
        t, diagnosis, steps, rejected, time.perf_counter() - wall0, integ.forced, integ.events
    )
