"""One sorting event: integrate a :class:`~.model.Scenario` in time.

:func:`simulate` integrates the :class:`~.model.SortingModel` of a scenario with
``solver.method``: our schemes (adaptive, trapezoidal, generalized_alpha), all in the one
compiled solve loop driven by ``stepper.Stepper``, or a SciPy ``solve_ivp`` baseline on the same
right-hand side (``baselines``: scipy:RK45, ...) whose points go through the same reductions;
either way the run is reduced to a :class:`~.result.SimulationResult`. The model and result
types live in ``model`` and ``result``; they are imported here too, where most callers look for
them.
"""

from __future__ import annotations

from .model import RECORDABLE, Scenario, SortingModel
from .result import EnergyAudit, SimulationResult
from .stepper import run

__all__ = [
    "RECORDABLE",
    "EnergyAudit",
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
        from .baselines import run_solve_ivp  # lazy: loads the kernel (Numba), SciPy

        return run_solve_ivp(model)
    return run(model)
