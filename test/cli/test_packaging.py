"""Package metadata that colcon and ros2 run rely on."""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

from fence_sorter import __version__

ROOT = Path(__file__).resolve().parents[2]
NODES = {"simulator", "scanner", "controller", "recorder"}


@pytest.mark.parametrize("path", ["package.xml", "msg_defs/package.xml"])
def test_package_xml_is_valid_format_3(path: str) -> None:
    package = parse_package(str(ROOT / path))
    package.validate()  # rejects, among others, a maintainer e-mail without a real domain
    assert package.package_format == 3
    assert package.version == __version__


def test_ament_python_layout() -> None:
    package = parse_package(str(ROOT / "package.xml"))
    assert package.name == "fence_sorter"
    assert package.get_build_type() == "ament_python"
    assert "fence_sorter_msgs" in {d.name for d in package.exec_depends}
    assert (ROOT / "resource" / "fence_sorter").is_file()
    setup_cfg = (ROOT / "setup.cfg").read_text()
    assert "script_dir=$base/lib/fence_sorter" in setup_cfg
    assert "install_scripts=$base/lib/fence_sorter" in setup_cfg


def test_interface_package() -> None:
    package = parse_package(str(ROOT / "msg_defs" / "package.xml"))
    assert package.name == "fence_sorter_msgs"
    assert package.get_build_type() == "ament_cmake"
    assert "rosidl_interface_packages" in {g.name for g in package.member_of_groups}
    assert "rosidl_default_generators" in {d.name for d in package.buildtool_depends}


def test_console_scripts() -> None:
    scripts = {
        ep.name: ep.value
        for ep in metadata.distribution("fence_sorter").entry_points
        if ep.group == "console_scripts"
    }
    for node in NODES:
        assert scripts[node] == f"fence_sorter.nodes.{node}:main"
    assert scripts["fence-sorter"] == "fence_sorter.cli.main:main"
