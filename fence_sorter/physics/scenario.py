"""The scenario of one sorting event: everything a user describes of it, as parameters.

Plain data, apart from the physics: the scene loader and the nodes that only read a scene (the
scanner) import this without the kernel, Numba or SciPy; ``model.SortingModel`` packs a
scenario for the kernel.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from .params import (
    ContactParams,
    ConveyorParams,
    DriveParams,
    FenceParams,
    ParcelParams,
    SolverParams,
)

RECORDABLE = ("trajectory", "fence", "forces", "stages")


@dataclass(frozen=True)
class Scenario:
    """Everything one sorting event needs (the scene loader builds it from YAML)."""

    conveyor: ConveyorParams = ConveyorParams()
    parcel: ParcelParams = ParcelParams()
    drive: DriveParams = DriveParams()
    contact: ContactParams = ContactParams()
    solver: SolverParams = SolverParams()
    fence: FenceParams | None = None  # None: stiff fence on a stiff drive
    fence_length: float = 1.2  # R_z [m] of a stiff fence (a flexible one uses fence.length)
    fence_modes: int | None = None  # modal truncation; None keeps every mode
    record: tuple[str, ...] = ()
    # initial (vx, vy, phidot) of C_s over ground; None = riding the belt at belt speed
    initial_velocity: tuple[float, float, float] | None = None
    # constant applied wrench (F_x, F_y, M_z) on the load, for checks and disturbances
    external_wrench: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def length(self) -> float:
        return self.fence.length if self.fence is not None else self.fence_length


T = TypeVar("T")
PER_SCENARIO_SIZE = 64  # scenarios each ``per_scenario`` cache keeps


def per_scenario(build: Callable[[Scenario], T]) -> Callable[[Scenario], T]:
    """``build(sc)`` computed once per :class:`Scenario` object and reused (what the kernel
    needs of a scene that is solved again and again: the optimiser, the line, the benchmarks).
    Keyed on the object's identity, not its hash: a Scenario is frozen, and hashing one hashes
    every field of every part (~1-2 us, as much as some of what is cached). Each entry holds
    its scenario, so the id cannot be reused while the entry is cached; a full cache is emptied
    (one atomic step, safe from any thread). The value is shared: nothing may modify it."""
    cache: dict[int, tuple[Scenario, T]] = {}

    @functools.wraps(build)
    def cached(sc: Scenario) -> T:
        hit = cache.get(id(sc))
        if hit is not None and hit[0] is sc:
            return hit[1]
        value = build(sc)
        if len(cache) >= PER_SCENARIO_SIZE:
            cache.clear()
        cache[id(sc)] = (sc, value)
        return value

    cached.cache = cache  # type: ignore[attr-defined]
    cached.cache_clear = cache.clear  # type: ignore[attr-defined] (as functools' caches)
    return cached
