"""Package metadata that colcon and ros2 run rely on."""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

from fence_sorter import __version__

ROOT = Path(__file__).resolve().parents[2]
NODES = {"simulator", "scanner", "controller", "recorder", "sensors"}


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


def test_resolver_reads_the_share_directory_without_a_checkout(tmp_path, monkeypatch):
    """No source checkout: bare names and package-relative paths resolve in the share directory
    of the ament prefix, and what is not there is not found (no fallback to the checkout)."""
    from fence_sorter import resources
    from fence_sorter.scene import resolve_scene
    from fence_sorter.stream import StreamError, resolve_stream

    prefix = tmp_path / "prefix"
    share = prefix / "share" / "fence_sorter"
    (share / "config" / "streams").mkdir(parents=True)
    (share / "config" / "scenes").mkdir()
    (share / "package.xml").write_text((ROOT / "package.xml").read_text())
    stream = share / "config" / "streams" / "mine.csv"
    stream.write_text("id\n")
    scene = share / "config" / "scenes" / "mine.yaml"
    scene.write_text("name: mine\n")
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / "fence_sorter"
    marker.parent.mkdir(parents=True)
    marker.write_text("")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    monkeypatch.setattr(resources, "checkout_root", lambda: None)
    monkeypatch.chdir(tmp_path)
    assert resources.data_root() == share
    assert resolve_stream("mine") == stream
    assert resolve_stream("config/streams/mine.csv") == stream
    assert resolve_scene("mine") == scene
    with pytest.raises(StreamError, match="stream default: file not found"):
        resolve_stream("default")
    assert resources.installed_files() == []


def test_resolver_finds_package_relative_paths_from_any_directory(tmp_path, monkeypatch):
    from fence_sorter.resources import data_path, find_data

    monkeypatch.chdir(tmp_path)
    manifest = find_data("config/streams", "config/streams/example_manifest.csv", ())
    assert manifest == data_path("config", "streams", "example_manifest.csv")
    assert manifest.is_file()
    assert find_data("config/streams", "no_such_stream", (".yaml",)) is None
