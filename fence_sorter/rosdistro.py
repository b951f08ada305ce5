"""Which ROS 2 distribution and which Fast DDS this environment runs on (ROS-free, no import of
rclpy): read from the installed wheels' metadata, else from an install's ``package.xml`` files.

Fast DDS 2.x (ROS 2 Jazzy) reads its XML profile only from ``FASTRTPS_DEFAULT_PROFILES_FILE``;
Fast DDS 3.x (Kilted) reads ``FASTDDS_DEFAULT_PROFILES_FILE`` and warns on the old name. A
profile under the wrong name is ignored without a word (default transports: sockets on every
interface), so the variable is chosen by the Fast DDS version found here.
"""

from __future__ import annotations

import os
import re
from functools import cache
from importlib import metadata
from pathlib import Path

#: the profile variable of each Fast DDS major version
PROFILE_VARIABLES = {2: "FASTRTPS_DEFAULT_PROFILES_FILE", 3: "FASTDDS_DEFAULT_PROFILES_FILE"}
#: the distribution of each rclpy major version (the wheels' ros-rclpy)
RCLPY_DISTRIBUTIONS = {7: "jazzy", 9: "kilted"}
#: Fast DDS's distribution names: the wheels' (ros-fastdds 3.x, ros-fastrtps 2.x) and the
#: ament package names of a ROS 2 install (share/<name>/package.xml)
FASTDDS_WHEELS = ("ros-fastdds", "ros-fastrtps")
FASTDDS_PACKAGES = ("fastdds", "fastrtps")


def _major(version: str) -> int | None:
    match = re.match(r"(\d+)", version)
    return int(match.group(1)) if match else None


def _wheel_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _package_xml_version(package: str) -> str | None:
    """``<version>`` of share/<package>/package.xml in the first prefix of AMENT_PREFIX_PATH
    that has it (a ROS 2 install from its own packages, no wheel metadata)."""
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        xml = Path(prefix, "share", package, "package.xml")
        if xml.is_file():
            match = re.search(r"<version>\s*([^<\s]+)\s*</version>", xml.read_text())
            if match:
                return match.group(1)
    return None


@cache
def fastdds_version() -> str | None:
    """Fast DDS's version string, or None when no Fast DDS is found."""
    for name in FASTDDS_WHEELS:
        version = _wheel_version(name)
        if version:
            return version
    for name in FASTDDS_PACKAGES:
        version = _package_xml_version(name)
        if version:
            return version
    return None


@cache
def ros_distribution() -> str | None:
    """The ROS 2 distribution's name: the one the wheels' rclpy version belongs to, else
    ``ROS_DISTRO`` of a sourced install; None when neither says."""
    version = _wheel_version("ros-rclpy")
    if version:
        return RCLPY_DISTRIBUTIONS.get(_major(version), f"rclpy {version}")
    return os.environ.get("ROS_DISTRO") or None


def profile_variables(version: str | None = None) -> tuple[str, ...]:
    """The variable(s) Fast DDS ``version`` (default: the one installed) reads its XML profile
    from; both names when the version is unknown, so the profile is never ignored."""
    version = fastdds_version() if version is None else version
    major = _major(version) if version else None
    if major in PROFILE_VARIABLES:
        return (PROFILE_VARIABLES[major],)
    if major is not None and major > max(PROFILE_VARIABLES):
        return (PROFILE_VARIABLES[max(PROFILE_VARIABLES)],)
    return tuple(PROFILE_VARIABLES.values())


def set_profile(env: dict[str, str], profile: str, version: str | None = None) -> None:
    """Point Fast DDS ``version`` (default: the one installed) at ``profile`` in ``env``, and
    remove the other name, which that version ignores or warns on."""
    names = profile_variables(version)
    for name in PROFILE_VARIABLES.values():
        if name in names:
            env[name] = profile
        else:
            env.pop(name, None)
