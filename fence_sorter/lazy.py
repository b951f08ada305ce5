"""Names of a package loaded from their modules on first use (PEP 562 module ``__getattr__``).

For packages whose ``__init__`` would otherwise import heavy modules (the physics and Numba) that
most importers of one light submodule never use: every node imports ``capacity.constraints`` and
``line.types``, ``fence-sorter optimize --help`` imports ``optimize.problem``. The one place of
that concept (``capacity``, ``line``, ``optimize``); docs/design/imports.md says which imports are
lazy, and :data:`HEAVY` which dependencies count as heavy (test/test_import_cycles.py and
``python -m benchmarks.imports`` read it).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from importlib import import_module

#: Dependencies loaded only where used, from ``python -X importtime -c "import M"`` (best of 3,
#: cumulative, docs/design/imports.md): Numba's compiler and the kernel (~0.4-1.6 s), SciPy's
#: submodules (0.6-1 s), rclpy (0.25 s) and the ROS message and ament packages (present only in
#: a ROS environment), Rerun (0.5 s), Dask's scheduler (1.6 s), Matplotlib (0.7-1.3 s), rosbags
#: and mcap (40-70 ms, only for bag files), websockets (0.1-0.3 s with asyncio, only to serve
#: Foxglove), CyRK (optional: only the compiled peers of the benchmark, ``cyrk:*``), pyarrow
#: (1.3 s with its Parquet module, only to write a Parquet file). numpy (80 ms), yaml and tqdm
#: are imported at the top.
HEAVY = frozenset(
    {
        "numba",
        "llvmlite",
        "scipy",
        "rclpy",
        "rcl_interfaces",
        "rosgraph_msgs",
        "diagnostic_msgs",
        "fence_sorter_msgs",
        "tf2_msgs",
        "geometry_msgs",
        "sensor_msgs",
        "std_msgs",
        "ament_index_python",
        "rerun",
        "dask",
        "distributed",
        "matplotlib",
        "rosbags",
        "mcap",
        "websockets",
        "CyRK",
        "pyarrow",
    }
)


def lazy_names(
    package: str, modules: Mapping[str, Sequence[str]]
) -> tuple[Callable[[str], object], list[str]]:
    """``__getattr__`` and ``__all__`` of ``package``: ``modules`` maps each module (absolute,
    or relative to the package) to the names it provides; a name is imported on first use and
    kept in the package."""
    where = {name: module for module, names in modules.items() for name in names}

    def __getattr__(name: str) -> object:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(where[name], package), name)
        setattr(sys.modules[package], name, value)
        return value

    return __getattr__, sorted(where)
