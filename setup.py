"""ament_python set-up of the fence_sorter package (colcon on ROS 2, pip -e . elsewhere)."""

import importlib.util
import re
from collections import defaultdict
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


def share_data_files() -> list[tuple[str, list[str]]]:
    """(share/fence_sorter/<dir>, [files]) for every run-time file: the files under the
    directories of fence_sorter/resources.py's SHARE_DIRS, the one list of them."""
    source = HERE / PACKAGE_NAME / "resources.py"
    spec = importlib.util.spec_from_file_location("resources", source)
    resources = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(resources)
    by_dir: dict[str, list[str]] = defaultdict(list)
    for rel in resources.installed_files():
        by_dir[str(Path(rel).parent)].append(rel)
    return [(f"share/{PACKAGE_NAME}/{d}", files) for d, files in sorted(by_dir.items())]


setup(
    name=PACKAGE_NAME,
    version=read_version(),
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "benchmarks.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE_NAME}"]),
        (f"share/{PACKAGE_NAME}", ["package.xml"]),
        ("bin", ["bin/fence-sorter"]),  # runs lib/fence_sorter/fence-sorter
        *share_data_files(),
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
            "sensors = fence_sorter.nodes.sensors:main",
            "foxglove_bridge = fence_sorter.nodes.foxglove_bridge:main",
            "line_unit = fence_sorter.nodes.line_unit:main",
            "line_owner = fence_sorter.nodes.line_owner:main",
            "line_viewer = fence_sorter.nodes.line_viewer:main",
            "fence-sorter = fence_sorter.cli.main:main",
        ],
    },
)
