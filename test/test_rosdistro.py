"""The ROS 2 distribution and Fast DDS version, and the profile variable chosen by the version
(fence_sorter.rosdistro): Fast DDS 2.x reads only FASTRTPS_DEFAULT_PROFILES_FILE, 3.x reads
FASTDDS_DEFAULT_PROFILES_FILE; a profile under the other name is ignored without a word."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

from fence_sorter import rosdistro
from fence_sorter.runner.processes import FASTDDS_PROFILE, node_env

OLD, NEW = "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"


@pytest.mark.parametrize(
    ("version", "names"),
    [
        ("2.14.5", (OLD,)),
        ("2.6.9", (OLD,)),
        ("3.2.3", (NEW,)),
        ("4.0.0", (NEW,)),
        ("", (OLD, NEW)),
        ("unknown", (OLD, NEW)),
    ],
)
def test_profile_variable_by_fastdds_version(version: str, names: tuple[str, ...]) -> None:
    assert rosdistro.profile_variables(version) == names


def test_set_profile_removes_the_name_the_version_does_not_read() -> None:
    env = {OLD: "/old.xml", NEW: "/new.xml", "OTHER": "x"}
    rosdistro.set_profile(env, "/p.xml", "2.14.5")
    assert env == {OLD: "/p.xml", "OTHER": "x"}
    rosdistro.set_profile(env, "/q.xml", "3.2.3")
    assert env == {NEW: "/q.xml", "OTHER": "x"}


def _venv_distribution() -> str | None:
    """The distribution scripts/bootstrap.sh set this venv up for (its own record)."""
    record = Path(sys.prefix) / ".fence_sorter_ros_distro"
    return record.read_text().strip() if record.is_file() else None


def _fastdds_library() -> str:
    """The Fast DDS shared library the wheels ship, as named on disk: libfastrtps.so.2.x
    (Fast DDS 2) or libfastdds.so.3.x (Fast DDS 3), in <venv>/lib."""
    lib = Path(sys.prefix, "lib")
    found = sorted(p.name for p in lib.glob("libfast*.so.*.*.*") if "cdr" not in p.name)
    assert found, f"no Fast DDS library in {lib}"
    return found[-1]


@pytest.mark.ros
def test_installed_distribution_and_fastdds_agree_with_the_venv_on_disk() -> None:
    """The version read from the metadata against the library file the wheel installed and
    against the venv's record of its distribution."""
    venv = _venv_distribution()
    if venv is None:
        pytest.skip("not a venv made by scripts/bootstrap.sh")
    assert rosdistro.ros_distribution() == venv
    version = rosdistro.fastdds_version()
    library = _fastdds_library()
    major = version.split(".")[0]
    expected = "libfastrtps.so." if major == "2" else "libfastdds.so."
    assert library.startswith(expected + ".".join(version.split(".")[:2])), (library, version)
    assert {"jazzy": "2", "kilted": "3"}[venv] == major
    assert metadata.version("ros-rclpy").split(".")[0] == {"jazzy": "7", "kilted": "9"}[venv]


@pytest.mark.ros
def test_node_env_points_the_installed_fastdds_at_the_localhost_profile(tmp_path: Path) -> None:
    env = node_env(150, tmp_path)
    (name,) = rosdistro.profile_variables()
    assert env[name] == str(FASTDDS_PROFILE)
    other = {OLD, NEW} - {name}
    assert not other & env.keys()


@pytest.mark.parametrize("value", ["humble", "Jazzy", " kilted"])
def test_bootstrap_refuses_an_unknown_distribution(value: str, tmp_path: Path) -> None:
    """A bad FENCE_SORTER_ROS_DISTRO: exit 2, one line naming it and the allowed values,
    before anything is made (the venv it would have used stays absent)."""
    repo = Path(__file__).resolve().parents[1]
    venv = tmp_path / "venv"
    proc = subprocess.run(
        ["bash", str(repo / "scripts" / "bootstrap.sh")],
        env={**os.environ, "FENCE_SORTER_ROS_DISTRO": value, "FENCE_SORTER_VENV": str(venv)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == (
        f"bootstrap: FENCE_SORTER_ROS_DISTRO must be jazzy or kilted, got '{value}'\n"
    )
    assert not venv.exists()
