"""ament_python set-up of the fence_sorter package (colcon on ROS 2, pip -e . elsewhere)."""

import re
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE_NAME = "fence_sorter"
HERE = Path(__file__).resolve().parent


def read_version() -> str:
    """Return __version__ from fence_sorter/__init__.py (the single source of the version)."""
    text = (HERE / PACKAGE_NAME / "__init__.py").read_text(encoding="utf-8")
    match = re.search(r'^__version__ = "([^"]+)"$', text, re.MULTILINE)
    if match is None:
        raise RuntimeError("fence_sorter/__init__.py does not define __version__")
    return match.group(1)


setup(
    name=PACKAGE_NAME,
    version=read_version(),
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE_NAME}"]),
        (f"share/{PACKAGE_NAME}", ["package.xml"]),
        (f"share/{PACKAGE_NAME}/config", sorted(glob("config/*.yaml"))),
        (f"share/{PACKAGE_NAME}/config/scenes", sorted(glob("config/scenes/*.yaml"))),
        (f"share/{PACKAGE_NAME}/launch", sorted(glob("launch/*.py"))),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fence_sorter maintainers",
    maintainer_email="fence-sorter@example.com",
    description="Digital twin of a rotary active fence parcel sorter (ROS 2, rosbag2, Rerun).",
    license="Apache-2.0",
    python_requires=">=3.10",
    extras_require={"test": ["pytest"]},
    entry_points={
        "console_scripts": [
            "simulator = fence_sorter.nodes.simulator:main",
            "scanner = fence_sorter.nodes.scanner:main",
            "controller = fence_sorter.nodes.controller:main",
            "recorder = fence_sorter.nodes.recorder:main",
            "fence-sorter = fence_sorter.cli.main:main",
        ],
    },
)
