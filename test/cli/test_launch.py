"""launch/sorter.launch.py: installed with the package; loads where launch_ros exists."""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import pytest

from fence_sorter.resources import installed_files

REPO = Path(__file__).resolve().parents[2]
LAUNCH = REPO / "launch" / "sorter.launch.py"


def test_launch_file_is_installed_and_names_every_node() -> None:
    tree = ast.parse(LAUNCH.read_text())
    funcs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in funcs
    executables = {
        kw.value.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "Node"
        for kw in node.keywords
        if kw.arg == "executable"
    }
    assert executables == {"simulator", "scanner", "controller", "recorder", "sensors"}
    assert "launch/sorter.launch.py" in installed_files()  # what setup.py installs


def test_the_launched_sensors_node_is_set_up_as_the_runner_sets_it_up() -> None:
    """launch_ros is not on the package registry, so the launch file is read as source: it
    declares a ``sensors`` argument and sets the sensors node, the simulator's publication and
    the noise seed up with the runner's own functions; those give parameters the nodes
    declare, within their ranges."""
    from fence_sorter.calibration.sensors import load_sensors
    from fence_sorter.nodes.parameters import NODE_PARAMETERS
    from fence_sorter.runner import job
    from fence_sorter.scene import load_scene

    tree = ast.parse(LAUNCH.read_text())
    declared = {
        node.args[0].value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "DeclareLaunchArgument"
    }
    assert declared == {"scene", "rtf", "stream", "parcels", "seed", "bag", "sensors"}
    imported = {
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module == "fence_sorter.runner.job"
        for alias in node.names
    }
    used = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    runner = {
        "sensors_node_parameters",
        "sensors_state_rate",
        "state_publish_rate",
        "sensors_seed",
    }
    assert runner <= imported & used
    # what those functions give a run with camera60 at rtf 1: declarable parameters
    rate = job.sensors_state_rate(
        load_sensors("camera60"), load_scene("impact_flexible").scenario, 1.0
    )
    params = job.sensors_node_parameters("impact_flexible", "camera60", 1, rate)
    specs = {s.name: s for s in NODE_PARAMETERS["sensors"]}
    assert set(params) <= set(specs)
    for key, value in params.items():
        assert specs[key].coerce(value) == value, key
    assert params["max_state_gap"] == pytest.approx(1.5 / 250.0)  # no lost state bridged
    publish = next(s for s in NODE_PARAMETERS["simulator"] if s.name == "publish_rate")
    assert publish.coerce(job.state_publish_rate(rate, 1.0)) == 250.0
    with pytest.raises(job.BadInput, match=r"--rtf must be in \(0, 4\]"):
        job.sensors_state_rate(load_sensors("camera60"), load_scene("impact_flexible").scenario, 0)


def test_launch_description_builds_with_launch_ros(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("launch_ros", reason="launch_ros is not installed (no full ROS 2)")
    import ament_index_python.packages as ament

    monkeypatch.setattr(ament, "get_package_share_directory", lambda pkg: str(REPO))
    spec = importlib.util.spec_from_file_location("sorter_launch", LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert len(description.entities) == 8  # 7 arguments + the nodes' OpaqueFunction
