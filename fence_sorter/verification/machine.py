"""What machine and revision a verification run ran on (shared by accuracy, stability, bench)."""

from __future__ import annotations

import os
import platform
import subprocess
from pathlib import Path

import numpy as np

#: where ``git`` looks for the revision: the package's own folder, inside a checkout's tree when
#: run from one; an installed copy is in none and reports "unknown"
PACKAGE_DIR = Path(__file__).resolve().parent


def _first_field(path: str, prefix: str) -> str | None:
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if line.startswith(prefix):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def machine_info() -> dict[str, str]:
    """CPU model, cores, memory, OS, Python and library versions, whether the JIT is on."""
    import numba  # lazy: Numba (0.4 s), only for its version
    import scipy

    cpu = _first_field("/proc/cpuinfo", "model name") or platform.processor() or platform.machine()
    mem_kib = _first_field("/proc/meminfo", "MemTotal")
    try:
        mem = f"{int(mem_kib.split()[0]) / 1024**2:.1f} GiB" if mem_kib else "unknown"
    except ValueError:
        mem = "unknown"
    try:
        usable = str(len(os.sched_getaffinity(0)))
    except AttributeError:
        usable = "?"
    return {
        "cpu": cpu,
        "cores": f"{os.cpu_count()} logical ({usable} usable by this process)",
        "memory": mem,
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "numba_jit": "disabled (NUMBA_DISABLE_JIT)" if numba.config.DISABLE_JIT else "enabled",
    }


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def _git(root: Path | str, *args: str) -> str:
    """The output of ``git -C root ARGS`` (CalledProcessError, OSError or a timeout)."""
    return subprocess.run(
        ["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10, check=True
    ).stdout.strip()


def git_revision(root: Path | str = PACKAGE_DIR) -> str:
    """Short HEAD, marked when tracked files differ from it."""
    try:
        rev = _git(root, "rev-parse", "--short", "HEAD")
        dirty = _git(root, "status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return rev + (" (working tree modified)" if dirty else "")
