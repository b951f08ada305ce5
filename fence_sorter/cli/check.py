"""``fence-sorter check``: is this environment able to run fence_sorter?

One line per check, ``OK`` or ``FAIL`` with what is missing and how to fix it; exit code 1 if
any check fails. Every import happens inside its check, so a broken environment gives a clear
message and never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from fence_sorter.rosdistro import fastdds_version, profile_variables, ros_distribution

PACKAGE = "fence_sorter"
MSG_PACKAGE = "fence_sorter_msgs"
EXPECTED_RMW = "rmw_fastrtps_cpp"
#: Node executables, used when the installed distribution metadata cannot be read.
NODE_EXECUTABLES: tuple[str, ...] = ("simulator", "scanner", "controller", "recorder", "sensors")
FIX = "run `make run` or scripts/bootstrap.sh, then `source scripts/env.sh`"


class CheckFailed(Exception):
    """A check found a problem; the message says what is missing and how to fix it."""


@dataclass(frozen=True)
class CheckResult:
    """Outcome of one check."""

    name: str
    ok: bool
    detail: str

    def line(self) -> str:
        """Return the line printed for this result."""
        return f"{'OK  ' if self.ok else 'FAIL'} {self.name}: {self.detail}"


def rmw_env_problem() -> str | None:
    """Return why the environment selects another RMW, or None.

    librcl checks RMW_IMPLEMENTATION and RCL_ASSERT_RMW_ID_MATCHES when it is loaded and ends
    the whole process (exit code 102) on a mismatch, so this is checked before importing rclpy.
    """
    for var in ("RMW_IMPLEMENTATION", "RCL_ASSERT_RMW_ID_MATCHES"):
        value = os.environ.get(var)
        if value and value != EXPECTED_RMW:
            return (
                f"{var}={value} but fence_sorter runs on {EXPECTED_RMW}, the one RMW it "
                f"installs (librcl would end the process at import); unset {var} or set it "
                f"to {EXPECTED_RMW}"
            )
    return None


def check_rclpy() -> str:
    """rclpy imports and its C extension loads."""
    problem = rmw_env_problem()
    if problem:
        raise CheckFailed(f"not imported: {problem}")
    try:
        import rclpy  # lazy: rclpy (0.25 s), only where ROS runs
        from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: F401
    except Exception as exc:  # ImportError, or OSError from a missing shared library
        raise CheckFailed(f"cannot import rclpy ({type(exc).__name__}: {exc}); {FIX}") from None
    return f"imported from {Path(rclpy.__file__).parent}"


def check_rmw() -> str:
    """The RMW implementation is Fast DDS."""
    problem = rmw_env_problem()
    if problem:
        raise CheckFailed(problem)
    try:
        # lazy: rclpy (0.25 s), only where ROS runs
        from rclpy.utilities import get_rmw_implementation_identifier

        identifier = get_rmw_implementation_identifier()
    except Exception as exc:
        raise CheckFailed(
            f"cannot load the RMW implementation ({type(exc).__name__}: {exc}); "
            f"install ros-rmw-fastrtps-cpp ({FIX})"
        ) from None
    if identifier != EXPECTED_RMW:
        requested = os.environ.get("RMW_IMPLEMENTATION")
        hint = f" (RMW_IMPLEMENTATION={requested})" if requested else ""
        raise CheckFailed(
            f"RMW is {identifier}{hint}, expected {EXPECTED_RMW}; unset RMW_IMPLEMENTATION"
        )
    return identifier


def check_distribution() -> str:
    """The ROS 2 distribution and Fast DDS version are known, and with them the variable that
    points Fast DDS at the run's transport profile."""
    distribution, fastdds = ros_distribution(), fastdds_version()
    if distribution is None:
        raise CheckFailed(f"no ROS 2 distribution found (no ros-rclpy, no ROS_DISTRO); {FIX}")
    if fastdds is None:
        raise CheckFailed(f"ROS 2 {distribution} without Fast DDS (ros-fastrtps/-fastdds); {FIX}")
    variables = " and ".join(profile_variables(fastdds))
    return f"{distribution}, Fast DDS {fastdds} (transport profile through {variables})"


def _msg_names() -> list[str]:
    try:
        from fence_sorter.recording.msgtypes import message_names  # lazy: loads rosbags

        return message_names()
    except Exception as exc:
        raise CheckFailed(f"cannot list the message definitions ({exc}); {FIX}") from None


def check_messages() -> str:
    """Every message of msg_defs/ imports from fence_sorter_msgs with the same fields."""
    names = _msg_names()
    try:
        module = importlib.import_module(f"{MSG_PACKAGE}.msg")
    except Exception as exc:
        raise CheckFailed(
            f"cannot import {MSG_PACKAGE}.msg ({type(exc).__name__}: {exc}); the interface "
            f"package is not built or not on the path; {FIX}"
        ) from None
    # lazy: loads rosbags
    from fence_sorter.recording.msgtypes import field_names, make_typestore, msgtype_name

    typestore = make_typestore()
    problems: list[str] = []
    for name in names:
        cls = getattr(module, name, None)
        if cls is None:
            problems.append(f"{name} missing")
            continue
        try:
            type(cls).__import_type_support__()
        except Exception as exc:
            problems.append(f"{name} type support does not load ({exc})")
            continue
        if getattr(cls, "_TYPE_SUPPORT", None) is None:
            problems.append(f"{name} type support does not load")
            continue
        built = list(cls.get_fields_and_field_types())
        defined = field_names(typestore, msgtype_name(name))
        if built != defined:
            problems.append(f"{name} fields {built} differ from msg_defs {defined} (stale build)")
    if problems:
        raise CheckFailed(f"{'; '.join(problems)}; {FIX}")
    return f"{len(names)} messages with type support: {', '.join(names)}"


def _node_executables() -> list[str]:
    """Return the console scripts of the installed fence_sorter that start nodes."""
    try:
        entry_points = metadata.distribution(PACKAGE).entry_points
    except metadata.PackageNotFoundError:
        return list(NODE_EXECUTABLES)
    names = [
        ep.name
        for ep in entry_points
        if ep.group == "console_scripts" and ep.value.startswith(f"{PACKAGE}.nodes.")
    ]
    return sorted(names) or list(NODE_EXECUTABLES)


def check_ament_index() -> str:
    """Every node executable resolves the way ``ros2 run fence_sorter <node>`` resolves it."""
    if not os.environ.get("AMENT_PREFIX_PATH"):
        raise CheckFailed("AMENT_PREFIX_PATH is not set; `source scripts/env.sh` (or " + FIX + ")")
    try:
        # lazy: loads the ament index (ROS only)
        from ament_index_python.packages import PackageNotFoundError, get_package_prefix
    except Exception as exc:
        raise CheckFailed(f"cannot import ament_index_python ({exc}); {FIX}") from None
    try:
        prefix = Path(get_package_prefix(PACKAGE))
    except PackageNotFoundError:
        raise CheckFailed(
            f"package {PACKAGE} is not in the ament index of AMENT_PREFIX_PATH="
            f"{os.environ['AMENT_PREFIX_PATH']}; {FIX}"
        ) from None
    problems: list[str] = []
    if not (prefix / "share" / PACKAGE / "package.xml").is_file():
        problems.append(f"{prefix}/share/{PACKAGE}/package.xml missing")
    try:
        get_package_prefix(MSG_PACKAGE)
    except PackageNotFoundError:
        problems.append(f"{MSG_PACKAGE} not in the ament index")
    executables = _node_executables()
    for exe in executables:
        path = prefix / "lib" / PACKAGE / exe
        if not path.is_file():
            problems.append(f"{path} missing")
        elif not os.access(path, os.X_OK):
            problems.append(f"{path} not executable")
    if problems:
        raise CheckFailed(f"{'; '.join(problems)}; {FIX}")
    return f"{prefix}/lib/{PACKAGE}/{{{','.join(executables)}}}"


def check_typestore() -> str:
    """The rosbags type store registers every message of msg_defs/."""
    try:
        # lazy: loads rosbags
        from fence_sorter.recording.msgtypes import find_msg_dir, make_typestore, msg_files
    except Exception as exc:
        raise CheckFailed(f"cannot import rosbags ({exc}); {FIX}") from None
    try:
        msg_dir = find_msg_dir()
        typestore = make_typestore(msg_dir)
    except Exception as exc:
        raise CheckFailed(f"{exc}") from None
    names = list(msg_files(msg_dir))
    missing = [name for name in names if name not in typestore.types]
    if missing:
        raise CheckFailed(f"not registered: {', '.join(missing)}")
    return f"{len(names)} types registered from {msg_dir}"


CHECKS: tuple[tuple[str, Callable[[], str]], ...] = (
    ("rclpy", check_rclpy),
    ("rmw", check_rmw),
    ("ros 2", check_distribution),
    (MSG_PACKAGE, check_messages),
    ("ament index", check_ament_index),
    ("rosbags typestore", check_typestore),
)


def run_checks() -> list[CheckResult]:
    """Run every check; a check that raises becomes a FAIL result, never a traceback."""
    results: list[CheckResult] = []
    for name, check in CHECKS:
        try:
            results.append(CheckResult(name, True, check()))
        except CheckFailed as exc:
            results.append(CheckResult(name, False, str(exc)))
        except Exception as exc:
            results.append(CheckResult(name, False, f"{type(exc).__name__}: {exc}; {FIX}"))
    return results


def run(args: argparse.Namespace) -> int:
    """Print one line per check; return 1 if any failed."""
    del args
    results = run_checks()
    for result in results:
        print(result.line())
    failed = [r.name for r in results if not r.ok]
    if failed:
        print(f"check: {len(failed)} of {len(results)} failed ({', '.join(failed)})")
        return 1
    print(f"check: all {len(results)} passed")
    sys.stdout.flush()
    return 0


def register(parser: argparse.ArgumentParser) -> None:
    """Configure the ``check`` subcommand."""
    parser.set_defaults(func=run)
