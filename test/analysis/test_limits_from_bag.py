"""``analyze`` judges each sorted parcel of a bag against the limits its controller planned
for (the controller's /diagnostics): the committed example bag, and a copy whose controller
planned for a lower exit speed limit ydot_dop (12) than one parcel delivered."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from bag_edit import rewrite_bag
from processes import run_cli

from fence_sorter.analysis.run import load_run, parcel_table, stream_summary
from fence_sorter.recording.bagread import read_bag

EXAMPLE = Path(__file__).resolve().parents[2] / "bags" / "example_4_parcels"


def test_the_example_bag_is_judged_against_its_controllers_limits() -> None:
    run = load_run(read_bag(EXAMPLE))
    got = {pid: o["impact_normal_speed"] for pid, o in run.outcomes.items() if o["sorted"]}
    # a w_dop between the two largest impact speeds of the bag's sorted parcels
    top, second = sorted(got.values())[-1], sorted(got.values())[-2]
    run.diagnostics["fence_sorter/controller"] = {
        "limits.w_dop": repr(0.5 * (top + second)),
        "limits.a_ndop": "300.0",
        "limits.ydot_dop": "2.5",
        "limits.active": "7,8,9,10,11,12",
    }
    rows = parcel_table(run)
    limits = stream_summary(run, rows)["limits"]
    worst = max(got, key=got.get)
    assert limits["over_limit"]["10"] == [worst] and not limits["clean"]
    assert limits["worst_excess"]["10"]["excess"] == got[worst] - 0.5 * (top + second)
    row = next(r for r in rows if r["parcel_id"] == worst)
    assert row["r_s_m"] == run.commands[worst]["r_s"] and row["t1_s"] == run.commands[worst]["t1"]
    assert row["mass_kg"] == run.parcels[worst]["mass"]


def test_analyze_exits_7_naming_the_parcels_over_the_controllers_limit(tmp_path) -> None:
    clean = run_cli("analyze", str(EXAMPLE), "--json", "--no-plots")
    assert clean.returncode == 0, clean.stderr
    assert json.loads(clean.stdout)["summary"]["limits"]["clean"]
    exits = {
        p["parcel_id"]: p["delivered_exit_speed_mps"]
        for p in json.loads(clean.stdout)["parcels"]
        if p["sorted"]
    }
    top, second = sorted(exits.values())[-1], sorted(exits.values())[-2]
    ydot_dop = 0.5 * (top + second)
    fast = max(exits, key=exits.get)

    def edit(msg):  # the controller planned for a lower ydot_dop than the paper's
        from rosbags.typesys.stores.ros2_jazzy import diagnostic_msgs__msg__KeyValue as KeyValue

        status = []
        for st in msg.status:
            if st.name == "fence_sorter/controller":
                extra = {"limits.w_dop": "2.4", "limits.a_ndop": "300.0"}
                extra |= {"limits.ydot_dop": repr(ydot_dop), "limits.active": "7,10,11,12"}
                st = replace(st, values=[*st.values, *(KeyValue(k, v) for k, v in extra.items())])
            status.append(st)
        return replace(msg, status=status)

    bag = tmp_path / "edited"
    rewrite_bag(EXAMPLE, bag, topic="/diagnostics", edit=edit)
    out = run_cli("analyze", str(bag), "--json", "--no-plots", "--out", str(tmp_path / "a"))
    assert out.returncode == 7, out.stderr
    limits = json.loads(out.stdout)["summary"]["limits"]
    assert limits["over_limit"] == {"7": [], "10": [], "11": [], "12": [fast]}
    assert limits["worst_excess"]["12"]["delivered"] == top
    assert limits["worst_excess"]["12"]["limit"] == ydot_dop
    assert f"(12) 1 sorted parcels over it [{fast}]" in out.stderr
    header = (tmp_path / "a" / "parcels.csv").read_text().splitlines()[0].split(",")
    assert {"r_s_m", "t1_s", "mass_kg", "delivered_exit_speed_mps", "over_limits"} <= set(header)
