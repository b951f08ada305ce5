"""Shared fixtures: an isolated ROS environment for the processes a test starts."""

from __future__ import annotations

from pathlib import Path

import pytest
from processes import ros_env, run_domain_id


def pytest_configure(config: pytest.Config) -> None:
    """Register the markers (also in setup.cfg) in case another config file wins."""
    config.addinivalue_line("markers", "ros: needs a working ROS 2 environment (rclpy, DDS)")
    config.addinivalue_line(
        "markers",
        "slow: takes seconds (processes, DDS, bags, full solves); "
        'pytest -m "not slow" is the quick run',
    )
    config.addinivalue_line(
        "markers",
        "faults: fault injection (signals, killed nodes; hostile, malformed and flooding input; "
        "bad files)",
    )
    config.addinivalue_line(
        "markers", "install: colcon build into a temporary install/, then runs from it"
    )
    config.addinivalue_line(
        "markers",
        "distro: the other ROS 2 distribution set up beside this one, the ROS and CLI tests "
        "run on it",
    )


@pytest.fixture(scope="session")
def domain_id() -> int:
    """ROS_DOMAIN_ID of this test run."""
    return run_domain_id()


@pytest.fixture
def env(domain_id: int, tmp_path: Path) -> dict[str, str]:
    """Environment for child processes: this run's domain, localhost discovery, own logs, and
    an own ROS_HOME (a recorder with no output_dir writes its bag there, not to ~/.ros)."""
    return ros_env(domain_id, tmp_path / "ros_log", {"ROS_HOME": str(tmp_path / "ros_home")})
