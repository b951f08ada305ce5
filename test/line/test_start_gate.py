"""The owner's start gate (:class:`~fence_sorter.line.lockstep.StartGate`): the first step of a
line waits for every unit of the line, on this host or another, and names the ones missing."""

from __future__ import annotations

from fence_sorter.line.lockstep import StartGate

NAMES = ("unit_1", "unit_2", "unit_3")


def test_the_gate_opens_only_when_every_unit_is_ready_and_matched() -> None:
    gate = StartGate(NAMES)
    assert gate.missing([True] * 3, True) == list(NAMES)
    gate.say_ready(0)
    gate.say_ready(2)
    # unit_2 (another host, not started yet) keeps the gate shut
    assert gate.missing([True] * 3, True) == ["unit_2"]
    gate.say_ready(1)
    assert gate.missing([True] * 3, True) == []
    # ready but the owner's commands to unit_3 not matched yet: still waiting for it
    assert gate.missing([True, True, False], True) == ["unit_3"]
    # the induction's link ends at the first unit
    assert gate.missing([True] * 3, False) == ["unit_1"]


def test_a_ready_from_outside_the_line_is_ignored() -> None:
    gate = StartGate(NAMES)
    for k in (-1, 3, 7):
        gate.say_ready(k)
    assert gate.ready == set()
    assert gate.missing([True] * 3, True) == list(NAMES)


def test_the_timeout_line_names_the_missing_units() -> None:
    msg = StartGate(NAMES).timeout_message(60.0, ["unit_2", "unit_3"])
    assert "\n" not in msg
    assert "start_timeout 60 s" in msg and "missing: unit_2, unit_3" in msg
