"""The run's exit status from its own stream (runner.summary): a divert parcel without an
outcome (3), foreign traffic (4: another run, forgeries with the run's id, foreign publishers),
a recorder that could not write (5), a disputed parcel (6), and the dropped and refused
message counters in the summary."""

from __future__ import annotations

import json

from fence_sorter.runner.monitor import Records
from fence_sorter.runner.summary import (
    EXIT_DISPUTED,
    EXIT_FOREIGN,
    EXIT_INCOMPLETE,
    EXIT_RECORDING,
    format_summary,
    summarise,
    summary_for_json,
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
    assert why == (
        "2 divert parcels of the run got no outcome: [3, 4]; divert parcels of the run not "
        "sorted: 3 (no outcome), 4 (no outcome)"
    )
    table = {row["parcel_id"]: row["outcome"] for row in s["parcels"]}
    assert table == {1: "SORTED", 2: "NOT_DIVERTED", 3: "MISSING", 4: "MISSING"}


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
    assert code == EXIT_FOREIGN and "5000 parcels and 7 commands of another run" in why
    assert why.endswith("divert parcels of the run not sorted: 1 (NO_COMMAND)")
    assert s["parcels_seen"] == 3 and s["divert"] == 2 and s["no_command"] == 1
    assert s["dropped"] == {"simulator": {"parcels.foreign": 5000, "commands.lost": 2}}
    text = format_summary(s)
    assert "foreign traffic   5000 parcels and 7 commands of another run" in text
    assert "without command   1 divert parcels got NO_COMMAND" in text
    assert "dropped (simulator) commands.lost 2, parcels.foreign 5000" in text


def test_forgeries_with_the_run_id_stay_out_of_the_figures_and_exit_4() -> None:
    """Forged parcels (the run's id, no valid tag) of real ids and of new ids, and an outcome
    for a parcel outside the stream: the figures cover the stream only, the exit names the
    forged ids of the run."""
    r = records(forged_parcels={2: 1, 3: 1, 9001: 1}, forged_commands={1: 2})
    r.outcomes = {
        1: outcome("SORTED", True),
        2: outcome("NOT_DIVERTED"),
        3: outcome("SORTED", True),
        9001: outcome("SORTED", True),  # a forged parcel that reached the line
    }
    s = summarise(r, 1.0, [1, 2, 3], [1, 3])
    code, why = verdict(s)
    assert code == EXIT_FOREIGN
    assert s["outcomes"] == 3 and s["sorted"] == 2 and s["outcomes_outside_stream"] == 1
    assert s["forged_parcel_messages"] == 3 and s["forged_command_messages"] == 2
    assert s["forged_parcel_ids"] == [2, 3]
    assert "forging parcel ids [2, 3] of the run" in why
    assert why.endswith("every divert parcel of the run was sorted")


def test_a_second_clock_publisher_is_named_and_exits_4() -> None:
    r = records()
    r.outcomes = {
        1: outcome("SORTED", True),
        2: outcome("NOT_DIVERTED"),
        3: outcome("SORTED", True),
    }
    r.diagnostics["fence_sorter/simulator"] = {
        "foreign_publishers./clock": "/intruder (gid 0102)",
        "foreign_publishers./parcels": "",
    }
    s = summarise(r, 1.0, [1, 2, 3], [1, 3])
    code, why = verdict(s)
    assert s["foreign_publishers"] == {"/clock": ["/intruder (gid 0102)"]}
    assert code == EXIT_FOREIGN and "publishers of /clock that are not the run's: /intruder" in why


def test_a_disputed_parcel_exits_6_naming_it() -> None:
    """Two specs for one id, seen by the monitor, flagged in an outcome or named by a node."""
    r = records(disputed={1})
    r.outcomes = {
        1: outcome("SORTED", True),
        2: {**outcome("NOT_DIVERTED"), "disputed": True},
        3: outcome("SORTED", True),
    }
    r.diagnostics["fence_sorter/controller"] = {
        "parcels.disputed_ids": "3",
        "parcels.conflict": "1",
    }
    s = summarise(r, 1.0, [1, 2, 3], [1, 3])
    code, why = verdict(s)
    assert code == EXIT_DISPUTED and s["disputed"] == [1, 2, 3]
    assert why.startswith("parcels of the run given two specs (disputed): [1, 2, 3]")
    assert [row["disputed"] for row in s["parcels"]] == [True, True, True]


def test_dropped_lists_every_refusal_counter_by_reason_and_no_total_twice() -> None:
    r = records()
    r.outcomes = {
        1: outcome("SORTED", True),
        2: outcome("NOT_DIVERTED"),
        3: outcome("SORTED", True),
    }
    r.diagnostics["fence_sorter/simulator"] = {
        "bad_parcels": "3",  # the totals of the per-reason counters below
        "commands_rejected": "2",
        "bad_parcels.mass": "2",
        "bad_parcels.scan_time": "1",
        "commands_rejected.duplicate": "2",
        "parcels_dropped_loop_down": "1",
        "parcels.rate_limited": "0",
    }
    r.diagnostics["fence_sorter/controller"] = {
        "rejected_parcels": "4",
        "rejected_parcels.duplicate_id": "4",
        "parcels.foreign": "7",
        "parcels.foreign_source": "3",
        "parcels.duplicate": "2",
        "parcels.conflict": "1",
        "parcels.disputed_ids": "5",  # ids, not a count
    }
    r.diagnostics["fence_sorter/sensors"] = {"bad_parcels.size": "1", "camera.lost": "5"}
    s = summarise(r, 1.0, [1, 2, 3], [1, 3])
    assert s["dropped"] == {
        "simulator": {
            "bad_parcels.mass": 2,
            "bad_parcels.scan_time": 1,
            "commands_rejected.duplicate": 2,
            "parcels_dropped_loop_down": 1,
        },
        "controller": {
            "rejected_parcels.duplicate_id": 4,
            "parcels.foreign": 7,
            "parcels.foreign_source": 3,
            "parcels.duplicate": 2,
            "parcels.conflict": 1,
        },
        "sensors": {"bad_parcels.size": 1, "camera.lost": 5},
    }
    # every refusal a node counts is in dropped: the per-reason counters add up to the totals
    sim = s["dropped"]["simulator"]
    assert sum(v for k, v in sim.items() if k.startswith("bad_parcels.")) == 3
    assert (
        "dropped (controller) parcels.conflict 1, parcels.duplicate 2, parcels.foreign 7, "
        "parcels.foreign_source 3, rejected_parcels.duplicate_id 4"
    ) in format_summary(s)


def test_a_recorder_write_error_exits_5_naming_the_error_and_where_the_bag_ends() -> None:
    r = records()
    r.outcomes = {
        1: outcome("SORTED", True),
        2: outcome("NOT_DIVERTED"),
        3: outcome("SORTED", True),
    }
    r.diagnostics["fence_sorter/recorder"] = {
        "bag": "/b",
        "write_error": "BagWriteError: /b: cannot flush segment b_1: [Errno 28] No space left",
        "write_failed_at_sim_s": "12.345",
        "bag_ends_sim_s": "11.900",
        "messages_dropped_write_failed": "4711",
    }
    s = summarise(r, 1.0, [1, 2, 3], [1, 3])
    code, why = verdict(s)
    assert code == EXIT_RECORDING == 5
    assert why == (
        "the bag could not be written: BagWriteError: /b: cannot flush segment b_1: [Errno 28] "
        "No space left at sim time 12.35 s; the bag holds every message up to sim time 11.90 s, "
        "the run went on unrecorded; every divert parcel of the run was sorted"
    )
    assert s["recording_failed"]["messages_not_written"] == 4711
    assert "recording FAILED  BagWriteError" in format_summary(s)
    # a divert parcel without an outcome is the graver verdict
    del r.outcomes[3]
    assert verdict(summarise(r, 1.0, [1, 2, 3], [1, 3]))[0] == EXIT_INCOMPLETE


#: the simulator's pacing diagnostics of an unpaced run: no deadlines, so no lateness figures
UNPACED = {
    "real_time_factor_target": "0",
    "real_time_factor_achieved": "26.203",
    "deadline_misses": "0",
    "cycle_lateness_p50_ms": "nan",
    "cycle_lateness_p99_ms": "nan",
    "cycle_lateness_max_ms": "0.0000",
    "publish_lag_max_ms": "nan",
}


def test_an_unpaced_run_shows_no_lateness_and_json_has_null_for_nan() -> None:
    r = records()
    r.outcomes = {1: outcome("SORTED", True), 2: outcome("NOT_DIVERTED")}
    r.diagnostics["fence_sorter/simulator"] = dict(UNPACED)
    s = summarise(r, 1.0, [1, 2], [1])
    line = next(x for x in format_summary(s).splitlines() if x.startswith("simulator"))
    assert line.split(None, 1)[1] == (
        "cycle_lateness n/a (unpaced), real_time_factor_target 0, real_time_factor_achieved 26.203"
    )
    text = json.dumps(summary_for_json(s), allow_nan=False)  # raises on a NaN left
    sim = json.loads(text)["simulator"]
    assert sim["cycle_lateness_p50_ms"] is None and sim["publish_lag_max_ms"] is None
    assert sim["cycle_lateness_max_ms"] == "0.0000" and sim["deadline_misses"] == "0"
    assert s["simulator"]["cycle_lateness_p50_ms"] == "nan"  # the summary keeps the node's text


def test_a_paced_runs_figure_the_node_could_not_take_reads_n_a() -> None:
    r = records()
    r.outcomes = {1: outcome("SORTED", True), 2: outcome("NOT_DIVERTED")}
    r.diagnostics["fence_sorter/simulator"] = {**UNPACED, "real_time_factor_target": "1"}
    line = next(
        x for x in format_summary(summarise(r, 1.0, [1, 2], [1])).splitlines()
        if x.startswith("simulator")
    )  # fmt: skip
    assert "nan" not in line
    assert "deadline_misses 0, cycle_lateness_p50_ms n/a" in line


def test_a_stream_the_guard_declines_half_of_is_called_too_dense() -> None:
    """One divert parcel of two declined sector_occupied (the controller's diagnostics) is
    half: the summary says the stream is denser than one fence sorts; none declined, or
    declines for other reasons, say nothing."""

    def summary(declined: dict[str, str]):
        r = records()
        r.outcomes = {
            1: outcome("SORTED", True),
            2: outcome("NOT_DIVERTED"),
            3: outcome("NO_FEASIBLE_COMMAND"),
        }
        r.diagnostics["fence_sorter/controller"] = declined
        return summarise(r, 1.0, [1, 2, 3], [1, 3])

    dense = format_summary(summary({"declined.sector_occupied": "1"}))
    assert "stream too dense  1 of 2 divert parcels declined sector_occupied" in dense
    for quiet in ({"declined.sector_occupied": "0"}, {"declined.no_feasible_stroke": "1"}):
        assert "stream too dense" not in format_summary(summary(quiet))
