"""`fence-sorter run` refuses bad input before starting anything: exit 2, one line."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from processes import run_cli, wait_until


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--parcels", "0"], "--parcels must be in [1, inf), got 0"),
        (["--rtf", "-1"], "--rtf must be in [0, 100] (0: unpaced), got -1.0"),
        (["--scene", "nope"], "scene nope: no such file or shipped scene"),
        (
            ["--sensors", "camera60", "--rtf", "0"],
            "--rtf must be in (0, 4] with --sensors camera60 (the state at 250 Hz of sim time, "
            "at most 1000 Hz of wall time), got 0",
        ),
        (["--sensors", "camera25", "--rtf", "6"], "--rtf must be in (0, 5] with --sensors"),
        (["--stream", "nope"], "stream nope: file not found"),
        (["--rrd", "x.txt"], "--rrd must be a .rrd file in an existing directory, got x.txt"),
        (["--rrd", "/nonexistent/x.rrd"], "--rrd must be a .rrd file in an existing directory"),
        (["--bag", "/dev/null/bag"], "--bag must be a directory that exists or can be made"),
        (
            ["--param", "controller.a_ndop=1"],
            "--param 'controller.a_ndop=1' must be NODE:KEY=VALUE",
        ),
        (
            ["--param", "controller:a_ndop=1e9"],
            "--param controller:a_ndop must be a double in [1e-06, 100000], got '1e9'",
        ),
        (
            ["--param", "controller:no_such_key=1"],
            "--param controller:no_such_key: controller has no parameter 'no_such_key'",
        ),
        (
            ["--param", f"simulator:loop_cpu={os.cpu_count()}"],
            f"--param simulator:loop_cpu must be an integer in [-1, {os.cpu_count() - 1}]",
        ),
        (
            ["--param", "simulator:loop_cpu=99"],
            f"--param simulator:loop_cpu must be an integer in [-1, {os.cpu_count() - 1}]",
        ),
        (
            ["--param", "controller:max_evaluations=2.5"],
            "--param controller:max_evaluations must be an integer in [1, 1000], got '2.5'",
        ),
        (
            ["--param", "simulator:warm_up=2"],
            "--param simulator:warm_up must be true or false, got '2'",
        ),
        (
            ["--param", "controller:w_dop=abc"],
            "--param controller:w_dop must be a double in [1e-06, 100], got 'abc'",
        ),
    ],
)
def test_bad_input_exits_2_with_one_line(args: list[str], message: str) -> None:
    proc = run_cli("run", *args, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fence-sorter: error: "), proc.stderr
    assert message in lines[0]


@pytest.mark.slow
def test_bad_manifest_names_line_and_column(tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text(
        "parcel_id,arrival_time,length_a,width_b,height,mass,divert\n1,0,0.4,0.3,0.3,x,true\n"
    )
    proc = run_cli("run", "--stream", str(bad), timeout=120)
    assert proc.returncode == 2
    assert f"manifest {bad} line 2 column 'mass'" in proc.stderr


def test_loop_cpu_comes_from_the_override_the_config_or_the_run(tmp_path: Path) -> None:
    from fence_sorter.runner.job import RunOptions, loop_cpu, prepare

    plan = prepare(RunOptions(parcels=2))
    # config/simulator.yaml leaves it to the run: the last CPU when paced on 2 CPUs or more
    assert loop_cpu(plan, 1.0, {0, 1}) == (1, True)
    assert loop_cpu(plan, 0.0, {0, 1}) == (-1, False)  # unpaced: the loop never sleeps
    assert loop_cpu(plan, 1.0, {0}) == (-1, False)
    opts = RunOptions(parcels=2, params=["simulator:loop_cpu=1", "simulator:loop_cpu=0"])
    assert loop_cpu(prepare(opts), 1.0, {0, 1}) == (0, False)  # the last override
    off = RunOptions(parcels=2, params=["simulator:loop_cpu=-1"])
    assert loop_cpu(prepare(off), 1.0, {0, 1}) == (-1, False)


@pytest.mark.slow
@pytest.mark.skipif(len(__import__("os").sched_getaffinity(0)) < 2, reason="needs 2 CPUs")
def test_process_group_keeps_its_nodes_on_the_cpus_it_is_given(tmp_path: Path) -> None:
    """Nodes start on every CPU (their imports use both); :meth:`ProcessGroup.confine` moves
    every thread of each onto the group's CPUs, and a node started after it inherits them."""
    import os
    import sys

    from fence_sorter.runner.processes import ProcessGroup, leftovers

    every = os.sched_getaffinity(0)
    cpus = {min(every)}
    group = ProcessGroup(dict(os.environ), tmp_path, cpus)
    # a node with a second thread, both blocked until the group stops it
    code = (
        "import threading; threading.Thread(target=threading.Event().wait, daemon=True).start(); "
        "threading.Event().wait()"
    )

    def threads_of(node) -> list[str] | None:
        tids = os.listdir(f"/proc/{node.proc.pid}/task")
        return tids if len(tids) > 1 else None

    try:
        early = group.start("early", [sys.executable, "-c", code])
        tids = wait_until(lambda: threads_of(early), 5.0, "the early node's second thread")
        assert all(os.sched_getaffinity(int(t)) == every for t in tids)
        group.confine()
        assert all(os.sched_getaffinity(int(t)) == cpus for t in tids)
        late = group.start("late", [sys.executable, "-c", code])
        tids = wait_until(lambda: threads_of(late), 5.0, "the late node's second thread")
        assert all(os.sched_getaffinity(int(t)) == cpus for t in tids)  # inherited
    finally:
        group.stop()
    assert not leftovers(group.pgids)


def test_the_controllers_damage_limits_reach_the_simulator():
    """The outcomes' margins are taken against the limits the controller plans with: a
    --param controller:w_dop is passed on to the simulator, unless it has its own."""
    from fence_sorter.runner.job import RunOptions, prepare

    plan = prepare(RunOptions(parcels=2, params=["controller:w_dop=2.0", "controller:a_ndop=150"]))
    assert plan.node_params["simulator"] == {"w_dop": 2.0, "a_ndop": 150.0}
    own = prepare(RunOptions(parcels=2, params=["simulator:w_dop=3.1", "controller:w_dop=2.0"]))
    assert own.node_params["simulator"] == {"w_dop": 3.1}
    assert "simulator" not in prepare(RunOptions(parcels=2)).node_params


def test_param_values_reach_the_nodes_as_the_type_they_declare() -> None:
    """An integer for a double widens (the README's controller:a_ndop=150), a string stays a
    string even when it reads as a number, every value as a typed ROS ``-p`` argument."""
    from fence_sorter.runner.job import RunOptions, _ros_args, prepare

    opts = RunOptions(
        parcels=2,
        params=[
            "controller:a_ndop=150",
            "controller:frame_id=42",
            "controller:active_constraints=[7, 10]",
            "simulator:warm_up=false",
            "simulator:lookahead=1e-2",
        ],
    )
    plan = prepare(opts)
    assert plan.node_params["controller"] == {
        "a_ndop": 150.0,
        "frame_id": "42",
        "active_constraints": [7, 10],
    }
    assert isinstance(plan.node_params["controller"]["a_ndop"], float)
    assert plan.node_params["simulator"] == {"warm_up": False, "lookahead": 0.01, "a_ndop": 150.0}
    args = _ros_args("controller", plan, opts, [])
    for given in ("a_ndop:=150.0", 'frame_id:="42"', "active_constraints:=[7, 10]"):
        assert given in args
    assert "warm_up:=false" in _ros_args("simulator", plan, opts, [])


@pytest.mark.slow
def test_every_node_table_is_ros_free_and_declarable() -> None:
    """The tables the runner checks against load without rclpy, and every default passes its
    own check (a node declares its defaults)."""
    import subprocess
    import sys

    code = (
        "import sys; import fence_sorter.nodes.parameters as p; "
        "assert 'rclpy' not in sys.modules, 'rclpy imported'; "
        "[s.coerce(s.default) for t in p.NODE_PARAMETERS.values() for s in t]; print('ok')"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.stdout.strip() == "ok", proc.stderr


def test_a_run_with_sensors_plans_their_state_rate_and_truth() -> None:
    """--sensors: the state at the highest sensor rate (at most 250 Hz of sim time, in the
    simulator's publish_rate units: wall Hz paced, sim Hz unpaced) and the truth the bag gets:
    the scene's fit values, the sensors file's content, the noise seed as the node gets it."""
    from fence_sorter.calibration.sensors import load_sensors
    from fence_sorter.runner.job import RunOptions, prepare, state_publish_rate
    from fence_sorter.scene import load_scene

    plan = prepare(RunOptions(parcels=2, sensors="camera25", seed=4))
    assert plan.state_rate == 200.0  # camera25: 200 Hz encoder, no gauge
    assert plan.truth["seed"] == 5 and plan.truth["sensors"] == "camera25"
    assert plan.truth["sensors_spec"]["camera"]["rate"] == load_sensors("camera25").camera.rate
    base = load_scene("impact_flexible").scenario
    assert plan.truth["values"]["mu_belt"] == base.conveyor.mu_belt
    assert plan.truth["values"]["fence.damping_ratio"] == base.fence.damping_ratio
    plan = prepare(RunOptions(parcels=2, sensors="camera60", params=["sensors:seed=9"]))
    assert plan.state_rate == 250.0 and plan.truth["seed"] == 9  # a 1 kHz gauge: capped
    assert state_publish_rate(250.0, 2.0) == 500.0 and state_publish_rate(250.0, 0.0) == 250.0
    assert state_publish_rate(250.0, 8.0) == 1000.0  # the parameter's upper end
    assert prepare(RunOptions(parcels=2)).truth is None


def test_the_recorders_custom_data_file_is_checked(tmp_path: Path) -> None:
    """What --sensors hands the recorder for the bag's metadata: a JSON object of strings;
    anything else is refused with a line naming the file (the recorder exits 2)."""
    from fence_sorter.nodes.recorder import read_custom_data_file

    good = tmp_path / "truth.json"
    good.write_text('{"fence_sorter.calibration_truth": "{\\"seed\\": 1}"}')
    assert read_custom_data_file(str(good)) == {"fence_sorter.calibration_truth": '{"seed": 1}'}
    assert read_custom_data_file("") == {}
    for text in ('{"a": 1}', "[1]", "{"):
        good.write_text(text)
        with pytest.raises(ValueError, match=f"custom_data_file {good}"):
            read_custom_data_file(str(good))
    with pytest.raises(ValueError, match="cannot read"):
        read_custom_data_file(str(tmp_path / "missing.json"))
