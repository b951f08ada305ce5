"""Names of a package loaded from their modules on first use (PEP 562 module ``__getattr__``).

For packages whose ``__init__`` would otherwise import heavy modules (the physics and Numba) that
most importers of one light submodule never use: every node imports ``capacity.constraints`` and
``line.types``, ``fence-sorter optimize --help`` imports ``optimize.problem``. The one place of
that concept (``capacity``, ``line``, ``optimize``); docs/design/imports.md says which imports are
lazy.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from importlib import import_module


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
