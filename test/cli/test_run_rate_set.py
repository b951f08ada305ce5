"""`fence-sorter run --rate` and `--set`: the plan's stream and scene, checked without ROS."""

from __future__ import annotations

from pathlib import Path

import pytest

from fence_sorter.cli.main import main
from fence_sorter.nodes.parameters import SCANNER_PARAMETERS
from fence_sorter.runner.job import (
    BadInput,
    RunOptions,
    prepare,
    scanner_stream_args,
    with_scene_file,
)
from fence_sorter.scene import load_scene
from fence_sorter.stream import load_stream

MASS_SPEED = ["parcel.mass=12", "conveyor.belt_speed=1.5"]


def test_rate_spaces_the_streams_parcel_mix_at_3600_over_rate_seconds():
    """The default stream: 2400 pcs/h, regular headways; its longest parcel's gap floor
    ((A + min_gap) / v < 0.9 s) is below either headway."""
    own = prepare(RunOptions(parcels=6)).stream
    slow = prepare(RunOptions(parcels=6, rate=1200.0)).stream
    for stream, headway in ((own, 1.5), (slow, 3.0)):
        times = [stream[i].arrival_time for i in sorted(stream)]
        assert [b - a for a, b in zip(times, times[1:], strict=False)] == pytest.approx(
            [headway] * 5, abs=1e-12
        )
    # the same parcels (the mix and its draws), only later
    for i in own:
        assert (slow[i].length_a, slow[i].width_b, slow[i].mass, slow[i].divert) == (
            own[i].length_a,
            own[i].width_b,
            own[i].mass,
            own[i].divert,
        )


def test_the_scanner_draws_the_plans_stream_at_the_rate():
    opts = RunOptions(parcels=4, rate=900.0, seed=3)
    plan = prepare(opts)
    args = scanner_stream_args(plan, opts)
    assert "rate:=900.0" in args and "parcels:=4" in args and "seed:=3" in args
    spec = {s.name: s for s in SCANNER_PARAMETERS}["rate"]
    assert (spec.default, spec.min_value, spec.max_value) == (0.0, 0.0, 1e5)
    # what the scanner node calls with those parameters
    drawn = load_stream(plan.stream_path, plan.belt_speed, count=4, seed=3, rate_pcs_h=900.0)
    assert [s.arrival_time for s in drawn] == [plan.stream[i].arrival_time for i in plan.stream]
    assert "rate:=" not in " ".join(scanner_stream_args(plan, RunOptions(parcels=4)))


@pytest.mark.parametrize(
    ("opts", "message"),
    [
        (RunOptions(rate=0.0), "--rate must be in [1, 100000] pcs/h, got 0"),
        (RunOptions(rate=2e5), "--rate must be in [1, 100000] pcs/h, got 200000"),
        (
            RunOptions(rate=1000.0, stream="example_manifest"),
            "a rate needs a stream config (YAML) to draw from, not a manifest",
        ),
        (RunOptions(overrides=["parcel.mass=-1"]), "parcel.mass must be in [0.01, 500] kg"),
        (RunOptions(overrides=["nope=1"]), "--set nope: nope is not a known key"),
        (RunOptions(overrides=["parcel.mass"]), "--set 'parcel.mass' must have the form"),
    ],
)
def test_bad_rate_or_set_is_refused_naming_it(opts: RunOptions, message: str):
    with pytest.raises(BadInput) as exc:
        prepare(opts)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_set_reaches_the_plan_and_the_scene_file_the_nodes_read(tmp_path: Path):
    plan = prepare(RunOptions(parcels=2, overrides=MASS_SPEED))
    assert plan.belt_speed == 1.5
    run_plan = with_scene_file(plan, tmp_path)
    assert run_plan.scene_path == tmp_path / "scene_set" / "impact_flexible.yaml"
    assert run_plan.run_id == plan.run_id and run_plan.stream == plan.stream
    written = load_scene(run_plan.scene_path)
    assert written.name == "impact_flexible"
    assert written.scenario == load_scene("impact_flexible", MASS_SPEED).scenario
    assert written.scenario.parcel.mass == 12.0
    # without --set the nodes read the scene file itself
    plain = prepare(RunOptions(parcels=2))
    assert with_scene_file(plain, tmp_path) is plain


def test_set_stiff_on_the_flexible_scene_writes_a_stiff_scene(tmp_path: Path):
    plan = with_scene_file(
        prepare(RunOptions(parcels=2, overrides=["fence.type=stiff"])), tmp_path
    )
    sc = load_scene(plan.scene_path).scenario
    assert sc.fence is None and sc.fence_length == 1.2


def test_cli_bad_rate_and_set_exit_2_in_one_line(capsys: pytest.CaptureFixture):
    assert main(["run", "--rate", "-5"]) == 2
    assert main(["run", "--set", "drive.t1=0"]) == 2
    assert main(["run", "--line", "two_units", "--set", "parcel.mass=3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3
    assert err[0] == "fence-sorter: error: --rate must be in [1, 100000] pcs/h, got -5"
    assert err[1].startswith("fence-sorter: error: scene impact_flexible.yaml: drive.t1 must")
    assert "--set" in err[2] and "do not go with --line" in err[2]
