"""The run's exit status from its own stream (runner.summary): a divert parcel without an
outcome (3), foreign traffic (4), and the dropped-message counters in the summary."""

from __future__ import annotations

from fence_sorter.runner.monitor import Records
from fence_sorter.runner.summary import (
    EXIT_FOREIGN,
    EXIT_INCOMPLETE,
    format_summary,
    summarise,
    verdict,
)


def outcome(name: str, sorted_: bool = False) -> dict:
    nan = float("nan")
    return {
        "sorted": sorted_,
        "reason": name.lower(),
        "reason_code": 0,
        "reason_name": name,
        "time": 1.0,
        "peak_normal_force": nan,
        "peak_normal_force_stiff": nan,
        "peak_normal_accel": nan,
        "impact_normal_speed": nan,
        "exit_speed_y": nan,
    }


def records(**kw) -> Records:
    r = Records(**kw)
    for pid, divert in ((1, True), (2, False), (3, True)):
        r.parcels[pid] = {"scan_time": float(pid), "scan_position_x": -3.0, "divert": divert}
    return r


def test_clean_run_has_no_verdict_and_no_drops() -> None:
    r = records()
    r.outcomes = {
        1: outcome("SORTED", True),
        2: outcome("NOT_DIVERTED"),
        3: outcome("SORTED", True),
    }
    s = summarise(r, 1.0, [1, 2, 3], [1, 3])
    assert verdict(s) is None and s["dropped"] == {} and s["divert_without_outcome"] == []


def test_divert_parcel_without_outcome_exits_3_even_if_never_seen() -> None:
    r = records()
    r.outcomes = {1: outcome("SORTED", True), 2: outcome("NOT_DIVERTED")}
    s = summarise(r, 1.0, [1, 2, 3, 4], [1, 3, 4])  # 4: in the stream, never on /parcels
    code, why = verdict(s)
    assert code == EXIT_INCOMPLETE and s["divert_without_outcome"] == [3, 4]
    assert "2 divert parcels of the run got no outcome: [3, 4]" == why


def test_foreign_traffic_exits_4_and_stays_out_of_the_figures() -> None:
    r = records(foreign_parcel_messages=5000, foreign_command_messages=7)
    r.outcomes = {1: outcome("NO_COMMAND"), 2: outcome("NOT_DIVERTED"), 3: outcome("SORTED", True)}
    r.diagnostics["fence_sorter/simulator"] = {
        "parcels.foreign": "5000",
        "parcels.received": "5003",
        "commands.lost": "2",
        "commands.rate_limited": "0",
        "take_errors": "0",
    }
    s = summarise(r, 1.0, [1, 2, 3], [1, 3])
    code, why = verdict(s)
    assert code == EXIT_FOREIGN and "5000 parcels, 7 commands of another run" in why
    assert s["parcels_seen"] == 3 and s["divert"] == 2 and s["no_command"] == 1
    assert s["dropped"] == {"simulator": {"parcels.foreign": 5000, "commands.lost": 2}}
    text = format_summary(s)
    assert "foreign traffic   5000 parcels, 7 commands" in text
    assert "without command   1 divert parcels got NO_COMMAND" in text
    assert "dropped (simulator) commands.lost 2, parcels.foreign 5000" in text
