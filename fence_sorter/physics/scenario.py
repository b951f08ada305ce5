"""The scenario of one sorting event: everything a user describes of it, as parameters.

Plain data, apart from the physics: the scene loader and the nodes that only read a scene (the
scanner) import this without the kernel, Numba or SciPy; ``model.SortingModel`` packs a
scenario for the kernel.
"""

from __future__ import annotations

from dataclasses import dataclass

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
