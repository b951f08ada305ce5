"""The package's run-time files: one resolver for a source checkout and for an install.

Node parameters (``config/<node>.yaml``), scenes (``config/scenes/``), parcel streams and CSV
manifests (``config/streams/``), the decision table, DDS profiles (``config/*.xml``), the robot
description (``urdf/``) and the launch file are read at run time. In a source checkout they
are the checkout's own files; in an install (``colcon build``, or any prefix that setup.py's
``data_files`` went to) they are under the package's share directory,
``<prefix>/share/fence_sorter``, found through the ament index as ``ros2 run`` finds it
(:func:`ament_index_python.packages.get_package_share_directory`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from pathlib import Path

PACKAGE = "fence_sorter"
#: directories of the package's run-time files; setup.py installs every file under them to
#: share/fence_sorter/<dir>/..., scripts/ament_layout.py links them into the venv's share
SHARE_DIRS = ("config", "launch", "urdf")


class ResourceNotFound(FileNotFoundError):
    """Neither a source checkout nor an installed share directory holds the file."""


def checkout_root() -> Path | None:
    """The source checkout this package is imported from, or None in an install."""
    root = Path(__file__).resolve().parents[1]
    if (root / "package.xml").is_file() and (root / "config").is_dir():
        return root
    return None


def share_dir() -> Path | None:
    """``share/fence_sorter`` of the ament prefix that installed the package, or None."""
    try:
        # lazy: loads the ament index (ROS only)
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(PACKAGE))
    except Exception:  # not in the ament index (AMENT_PREFIX_PATH), or no ament_index_python
        pass
    # a plain install into this interpreter's prefix (pip install without the ament index)
    candidate = Path(sys.prefix) / "share" / PACKAGE
    return candidate if (candidate / "package.xml").is_file() else None


def data_root() -> Path:
    """Where the run-time files are: the checkout, else the installed share directory."""
    root = checkout_root() or share_dir()
    if root is None:
        raise ResourceNotFound(
            f"{PACKAGE}: no source checkout and no installed share/{PACKAGE} "
            f"(AMENT_PREFIX_PATH={os.environ.get('AMENT_PREFIX_PATH', '')!r})"
        )
    return root


def data_path(*parts: str) -> Path:
    """A run-time file or directory by its path relative to the package, e.g.
    ``data_path("config", "simulator.yaml")`` (it need not exist)."""
    return data_root().joinpath(*parts)


def find_data(directory: str, name: str | Path, suffixes: Sequence[str]) -> Path | None:
    """The file a user names: an existing path as given; else a relative path (e.g.
    "config/streams/example_manifest.csv") in the package's files; else a bare name, with or
    without one of ``suffixes``, in the package's ``directory`` (e.g. "config/streams").
    None if none of them is a file."""
    path = Path(name).expanduser()
    if path.is_file():
        return path
    text = str(name)
    try:
        if "/" in text or "\\" in text:
            candidates = [] if path.is_absolute() else [data_path(text)]
        else:
            base = data_path(*directory.split("/"))
            candidates = [base / text] + [base / f"{text}{suffix}" for suffix in suffixes]
    except ResourceNotFound:
        return None
    return next((c for c in candidates if c.is_file()), None)


def installed_files() -> list[str]:
    """Every run-time file of the checkout as a path relative to it (what setup.py installs
    into share/fence_sorter); empty in an install."""
    root = checkout_root()
    if root is None:
        return []
    return sorted(
        str(p.relative_to(root))
        for d in SHARE_DIRS
        for p in (root / d).rglob("*")
        if p.is_file() and "__pycache__" not in p.parts
    )
