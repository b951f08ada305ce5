"""One sorting event: integrate a :class:`~.model.Scenario` in time.

:func:`simulate` integrates the :class:`~.model.SortingModel` of a scenario with
``solver.method``: our schemes (adaptive, trapezoidal, generalized_alpha), all in the one
compiled solve loop driven by ``stepper.Stepper``, or a SciPy ``OdeSolver`` baseline on the
same right-hand side (``baselines.ScipyStepper``: scipy:RK45, ...) whose points go through the
same reductions; both are stepped through one interface (``stepper.SolveStepper``,
:func:`solve_stepper`) and the run is reduced to a :class:`~.result.SimulationResult`. The
model and result types live in ``model`` and ``result``; they are imported here too, where
most callers look for them.
"""

from __future__ import annotations

from .model import RECORDABLE, Scenario, SortingModel
from .result import EnergyAudit, SimulationResult
from .stepper import SolveStepper, Stepper, run

__all__ = [
    "RECORDABLE",
    "EnergyAudit",
    "Scenario",
    "SimulationResult",
    "SortingModel",
    "simulate",
    "solve_stepper",
]


def solve_stepper(model: SortingModel) -> SolveStepper:
    """The stepper of ``model.sc.solver.method``: our schemes' :class:`~.stepper.Stepper`, a
    SciPy baseline's :class:`~.baselines.ScipyStepper` or a compiled peer's
    :class:`~.peers.CyrkStepper`; all step alike (``SolveStepper``)."""
    if model.sc.solver.method.startswith("scipy:"):
        # scipy.integrate and scipy.optimize take ~0.7 s to import (python -X importtime);
        # only the baselines need them
        from .baselines import ScipyStepper  # lazy: loads SciPy

        return ScipyStepper(model)
    if model.sc.solver.method.startswith("cyrk:"):
        # CyRK is a benchmark dependency; the peer's module compiles its diffeq on first use
        from .peers import CyrkStepper  # lazy: loads CyRK

        return CyrkStepper(model)
    return Stepper(model)


def simulate(sc: Scenario, model: SortingModel | None = None) -> SimulationResult:
    """Run one sorting event from drive start (t = 0) to sorted or the end time."""
    return run(solve_stepper(model or SortingModel(sc)))
