"""Compiled force evaluation, one-step maps and solve loop of the sorting model (Numba).

This package is the one implementation of the forces of one sorting event: the fence surface
(21)-(32), the contact law (16) with fence and border friction (37), belt friction (34)-(36) and
the fence's modal load (20). Its modules: ``layout`` (the arrays' records, :func:`pack`),
``forces`` (:func:`evaluate`), ``steps`` (the one-step maps), ``rhs`` (the ODE form of the
SciPy baselines), ``impact`` (N_stiff), ``control`` (propagators, error estimate, events),
``loop`` (:func:`solve`), ``observer`` (:func:`observe`, the reductions of a run at its
accepted points, and the divergence checks) and ``aot`` (the loop compiled ahead of time into
an extension module, which :data:`solve` calls when it is built for these sources); every name
is importable from the package. Everything works on NumPy arrays so that Numba compiles it:

- ``P``: the event's parameters, an array of one :data:`PARAMS` record (``P[0].mass``),
  built by :func:`pack`; the loop's ``settings``, ``counters`` and ``figures`` are records
  too (``layout``);
- ``y``: the state [x, y, phi, vx, vy, phidot, eta_1..m, etadot_1..m] (C_s over ground, yaw,
  their rates, then the fence's modal coordinates and rates; m = 0 for a stiff fence);
- ``out``: one :data:`CONTACT` record per contact slot (0-3 corner k on the fence, 4-7 the
  fence tip in face k, 8-11 corner k on the border wall), ``out[k].d``;
- ``res``: the resultant and a few scalars, an array of one :data:`RESULT` record
  (``res[0].fx``).

Why compiled: the pure-Python stepper ran impact_flexible at 2.4x real time; the accuracy and
speed targets (75x real time) need the force evaluation in the 1-10 us range, which only a
compiled kernel reaches (docs/reports/benchmarks.md measures the same code with and without the
JIT). Setting NUMBA_DISABLE_JIT=1 runs exactly this code as plain Python.

Compiled without Numba's reference counting (``_nrt=False``, as Numba compiles its own hot
functions): every array here is allocated by the caller, and with NRT each call of a kernel
function and each view (``Y[a]``, ``out[slot]``) pays an atomic incref/decref per array, 139,000
per positioned_stiff event, half its run time (perf; counted with gdb on NRT_incref/decref).
The two functions that allocate (``modal_propagators``, ``generalized_alpha_step``) say
``_nrt=True`` explicitly: a callee otherwise inherits the flag of whoever compiles it first.

The small functions of the contact iteration (``_add``, ``_surface``, ``_fence_friction``,
``implicit_belt``, ``belt_multiplier``, ``_friction_prev``, ``_newton_load``) are inlined into
their callers by Numba (``inline="always"``): a call passes every array as ~7-9 machine words,
and the profile showed the callers pushing ~150 words per ``_evaluate`` call and dozens per
``_add`` (same arithmetic, bitwise the same results; compiled loop 5-12 % faster,
docs/design/numerics.md).

The time-stepping schemes built on it (trapezoidal, generalized-alpha) are the ``*_step``
functions of ``steps``. :func:`solve` is the one control loop of every scheme (events, step
size, stages, recording), driven by ``stepper.Stepper`` (``simulate`` and the soft-real-time
line); under NUMBA_DISABLE_JIT=1 the same source is the Python reference.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import numba


def source_digest(package: Path = Path(__file__).parent) -> str:
    """A hash of every module of this package: the key of Numba's cache and of the
    ahead-of-time solve (``aot``)."""
    digest = hashlib.sha256()
    for path in sorted(package.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_directory(package: Path = Path(__file__).parent) -> Path:
    """Numba's on-disk cache of this package, keyed on a hash of all its sources.

    Numba checks a cached function against its own file only, so a change to a callee in
    another module (``forces._evaluate`` inlined into ``steps.trapezoidal_step``) would leave
    the caller's cached machine code stale. With the directory named after the hash of every
    module here, any change starts a fresh cache. Under NUMBA_CACHE_DIR when that is set, else
    in the package's __pycache__, where the caches (and ahead-of-time builds, ``aot-*``) of
    earlier sources are removed."""
    name = "numba-" + source_digest(package)[:16]
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return Path(user) / name
    base = package / "__pycache__"
    if base.is_dir():
        for old in (*base.glob("numba-*"), *base.glob("aot-*")):
            if old.name not in (name, "aot-" + name[6:]):
                shutil.rmtree(old, ignore_errors=True)
    return base / name


# before the modules below are imported: their decorators read it (cache=True)
numba.config.CACHE_DIR = str(cache_directory())

from . import control, layout  # noqa: E402 (after the cache directory is set)
from .aot import Solve, aot_directory  # noqa: E402 (after the cache directory is set)
from .control import *  # noqa: E402, F403 (every name of control.__all__, re-exported)
from .forces import (  # noqa: E402 (after the cache directory is set)
    belt_multiplier,
    drive,
    evaluate,
    fence_shape,
    implicit_belt,
    karnopp_belt,
    stick_wrench,
    surface,
)
from .impact import (  # noqa: E402 (after the cache directory is set)
    _N_STIFF_CHEBYSHEV,
    N_STIFF_C_MAX,
    N_STIFF_DEGREE,
    N_STIFF_FIT_STEPS,
    N_STIFF_STEPS,
    n_stiff,
    n_stiff_coefficients,
    stiff_impact_peak,
    stiff_impact_peak_force,
)
from .layout import *  # noqa: E402, F403 (every name of layout.__all__, re-exported)
from .loop import (  # noqa: E402 (after the cache directory is set)
    EVENT_SORT,
    EVENT_TOL,
    SOLVE_DONE,
    SOLVE_GROW,
    SOLVE_PAUSED,
    SOLVE_REACHED,
)
from .loop import solve as _solve_jit  # noqa: E402 (after the cache directory is set)
from .observer import (  # noqa: E402 (after the cache directory is set)
    FLUSH_ANGLE,
    STAGE_CODE_E1,
    STAGE_CODE_E2,
    STAGE_CODE_E3,
    STAGE_CODE_E4,
    STAGE_CODE_ON_BELT,
    STAGE_CODE_SORTED,
    classify_code,
    diverged,
    observe,
    parabola_peak,
)
from .rhs import (  # noqa: E402 (after the cache directory is set)
    rhs,
)
from .steps import (  # noqa: E402 (after the cache directory is set)
    NEWTON,
    STEP_FORCED,
    STEP_OK,
    STEP_REJECTED,
    generalized_alpha_step,
    trapezoidal_step,
    trapezoidal_work_shape,
)

# the loop's entry: the ahead-of-time extension when it is built for these sources (a first
# solve without Numba's dispatcher, ``aot``), the JIT dispatcher otherwise
solve = Solve(_solve_jit, aot_directory(Path(numba.config.CACHE_DIR)), source_digest())

__all__ = [
    *layout.__all__,
    *control.__all__,
    "belt_multiplier",
    "drive",
    "evaluate",
    "fence_shape",
    "implicit_belt",
    "karnopp_belt",
    "stick_wrench",
    "surface",
    "generalized_alpha_step",
    "NEWTON",
    "STEP_FORCED",
    "STEP_OK",
    "STEP_REJECTED",
    "trapezoidal_step",
    "trapezoidal_work_shape",
    "rhs",
    "_N_STIFF_CHEBYSHEV",
    "n_stiff",
    "N_STIFF_C_MAX",
    "n_stiff_coefficients",
    "N_STIFF_DEGREE",
    "N_STIFF_FIT_STEPS",
    "N_STIFF_STEPS",
    "stiff_impact_peak",
    "stiff_impact_peak_force",
    "diverged",
    "classify_code",
    "EVENT_SORT",
    "EVENT_TOL",
    "FLUSH_ANGLE",
    "observe",
    "parabola_peak",
    "solve",
    "SOLVE_DONE",
    "SOLVE_GROW",
    "SOLVE_PAUSED",
    "SOLVE_REACHED",
    "STAGE_CODE_E1",
    "STAGE_CODE_E2",
    "STAGE_CODE_E3",
    "STAGE_CODE_E4",
    "STAGE_CODE_ON_BELT",
    "STAGE_CODE_SORTED",
]
