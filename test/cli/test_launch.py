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
    assert executables == {"simulator", "scanner", "controller", "recorder"}
    assert "launch/sorter.launch.py" in installed_files()  # what setup.py installs


def test_launch_description_builds_with_launch_ros(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("launch_ros", reason="launch_ros is not installed (no full ROS 2)")
    import ament_index_python.packages as ament

    monkeypatch.setattr(ament, "get_package_share_directory", lambda pkg: str(REPO))
    spec = importlib.util.spec_from_file_location("sorter_launch", LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert len(description.entities) == 10  # 6 arguments + 4 nodes
