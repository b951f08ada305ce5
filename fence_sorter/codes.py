"""The integer codes of the sorter's messages as enums (fence_sorter_msgs: SortOutcome,
LoadState, FenceCommand), in one light module: the line, the node layer, the run's monitor and
the bag analysis all name codes from here (test/ros/test_convert_line.py checks them against
the generated message constants)."""

from __future__ import annotations

from enum import IntEnum


class OutcomeCode(IntEnum):
    """SortOutcome.reason_code values."""

    SORTED = 0
    NOT_DIVERTED = 1
    NO_FEASIBLE_COMMAND = 2
    NO_COMMAND = 3
    MISSED = 4
    REJECTED = 5
    SOLVER_FAILURE = 6
    NO_STROKE_IN_BUDGET = 7


class Stage(IntEnum):
    """A load's motion stage (paper section 2): the LoadState.stage values, the solve loop's
    stage codes (``kernel.STAGE_CODE_*``) and, by :attr:`label`, the stage strings of results,
    JSON, CSV and bags."""

    ON_BELT = 0
    E1 = 1
    E2 = 2
    E3 = 3
    E4 = 4
    SORTED = 5
    PASSED = 6

    @property
    def label(self) -> str:
        """The stage's string in results and files: ``on_belt``, ``E1``-``E4``, ``sorted``,
        ``passed``."""
        return self.name if self.name[0] == "E" else self.name.lower()


class StartMode(IntEnum):
    """FenceCommand.start_mode values."""

    AT_RS = 0  # start the working motion when the parcel front reaches r_s
    AT_TIME = 1  # start the working motion at start_time


#: the reason of a controller's "no stroke" whose planning ran out of time (deadline or cap)
#: with candidates left starts with this; a FenceCommand carries the reason, not the code
BUDGET_REASON = "planning budget ran out"


def decline_code(reason: str) -> OutcomeCode:
    """The outcome of a parcel whose command says "no stroke" with ``reason``:
    NO_STROKE_IN_BUDGET when planning ran out of time, else NO_FEASIBLE_COMMAND."""
    if reason.startswith(BUDGET_REASON):
        return OutcomeCode.NO_STROKE_IN_BUDGET
    return OutcomeCode.NO_FEASIBLE_COMMAND


def code_name(enum: type[IntEnum], value: int) -> str:
    """Name of ``value`` in ``enum``; ``CODE_<n>`` for a value the enum does not know (a bag or
    peer from another version)."""
    try:
        return enum(int(value)).name
    except ValueError:
        return f"CODE_{int(value)}"
