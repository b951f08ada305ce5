"""The ``fence-sorter`` command line: version, subcommand registry, check, demo-roundtrip."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import pytest
from processes import managed_process, venv_executable

from fence_sorter import __version__
from fence_sorter.cli import main as cli_main

FENCE_SORTER = venv_executable("fence-sorter")
TIMEOUT = 60.0
CHECK_NAMES = ("rclpy", "rmw", "ros 2", "fence_sorter_msgs", "ament index", "rosbags typestore")


def run_cli(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    with managed_process([FENCE_SORTER, *args], env) as proc:
        out, err = proc.communicate(timeout=TIMEOUT)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.mark.slow
def test_version_console_script(env: dict[str, str]) -> None:
    result = run_cli(["--version"], env)
    assert result.returncode == 0
    assert result.stdout.strip() == f"fence-sorter {__version__}"


def test_version_is_single_sourced() -> None:
    from importlib import metadata

    assert metadata.version("fence_sorter") == __version__
    package_xml = Path(__file__).resolve().parents[2] / "package.xml"
    assert f"<version>{__version__}</version>" in package_xml.read_text()


def test_every_subcommand_module_configures_its_parser() -> None:
    import importlib

    assert "check" in cli_main.SUBCOMMANDS and "demo-roundtrip" in cli_main.SUBCOMMANDS
    for command in cli_main.SUBCOMMANDS:
        module = importlib.import_module(cli_main.module_name(command))
        parser = argparse.ArgumentParser(prog=command)
        module.register(parser)
        assert callable(parser._defaults.get("func")), f"{command} has no func"
    parser = cli_main.build_parser()
    assert "check" in parser.format_help() and "demo-roundtrip" in parser.format_help()


def test_only_the_chosen_subcommand_module_is_imported() -> None:
    """``fence-sorter simulate --help`` imports cli.simulate, no other subcommand module and
    none of the heavy dependencies (the kernel, SciPy, rclpy)."""
    code = (
        "import sys\n"
        "from fence_sorter.cli import main\n"
        "try:\n"
        "    main.main(['simulate', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "heavy = ('numba', 'scipy', 'rclpy', 'fence_sorter.physics.kernel')\n"
        "loaded = [m for m in sys.modules if m.startswith('fence_sorter.cli.')]\n"
        "loaded += [m for m in heavy if m in sys.modules]\n"
        "print(' '.join(sorted(loaded)), file=sys.stderr)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=TIMEOUT
    )
    assert proc.returncode == 0, proc.stderr
    assert "--set KEY=VALUE" in proc.stdout
    assert proc.stderr.split() == ["fence_sorter.cli.main", "fence_sorter.cli.simulate"]


def test_broken_subcommand_module_does_not_break_the_others(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(cli_main.SUBCOMMANDS, "no-such-module", "a module that is not there")
    assert cli_main.main(["no-such-module"]) == 1
    assert "fence_sorter.cli.no_such_module cannot be loaded" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        cli_main.main(["--version"])
    assert exc.value.code == 0


def test_no_subcommand_prints_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main.main([]) == 2
    assert "check" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.ros
def test_check_passes_in_the_bootstrapped_env(env: dict[str, str]) -> None:
    result = run_cli(["check"], env)
    assert result.returncode == 0, result.stdout + result.stderr
    for name in CHECK_NAMES:
        assert f"OK   {name}:" in result.stdout
    assert "FAIL" not in result.stdout
    # the distribution and Fast DDS, against the venv's record and the library file on disk
    record = Path(sys.prefix) / ".fence_sorter_ros_distro"
    if record.is_file():
        distro = record.read_text().strip()
        lib = Path(sys.prefix, "lib")
        library = next(
            p.name for p in sorted(lib.glob("libfast*.so.*.*.*")) if "cdr" not in p.name
        )
        major_minor = ".".join(library.split(".so.")[1].split(".")[:2])
        variable = "FASTRTPS" if major_minor.startswith("2.") else "FASTDDS"
        line = next(ln for ln in result.stdout.splitlines() if ln.startswith("OK   ros 2:"))
        assert line.startswith(f"OK   ros 2: {distro}, Fast DDS {major_minor}."), line
        assert line.endswith(f"(transport profile through {variable}_DEFAULT_PROFILES_FILE)")


def _shadow_package(root: Path, name: str, body: str) -> Path:
    """A package ``name`` under ``root`` that hides the real one (PYTHONPATH comes first)."""
    package = root / name
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(body)
    return root


def _assert_fails_cleanly(result: subprocess.CompletedProcess, failing: str, *words: str) -> str:
    output = result.stdout + result.stderr
    assert result.returncode == 1, output
    assert "Traceback" not in output
    line = next((ln for ln in result.stdout.splitlines() if ln.startswith(f"FAIL {failing}:")), "")
    assert line, output
    for word in words:
        assert word in line, line
    assert "bootstrap" in line or "unset" in line, line
    return line


@pytest.mark.slow
@pytest.mark.ros
def test_check_names_unbuilt_messages(env: dict[str, str], tmp_path: Path) -> None:
    # A fence_sorter_msgs without its generated msg module, as after a failed build.
    shadow = _shadow_package(tmp_path / "shadow", "fence_sorter_msgs", "")
    env["PYTHONPATH"] = str(shadow)
    result = run_cli(["check"], env)
    _assert_fails_cleanly(result, "fence_sorter_msgs", "fence_sorter_msgs.msg")
    assert "OK   rclpy:" in result.stdout  # the other checks still run


@pytest.mark.slow
@pytest.mark.ros
def test_check_names_broken_rclpy(env: dict[str, str], tmp_path: Path) -> None:
    body = "raise ImportError('librmw_fastrtps_cpp.so: cannot open shared object file')\n"
    env["PYTHONPATH"] = str(_shadow_package(tmp_path / "shadow", "rclpy", body))
    result = run_cli(["check"], env)
    _assert_fails_cleanly(result, "rclpy", "librmw_fastrtps_cpp.so")
    _assert_fails_cleanly(result, "rmw")


@pytest.mark.slow
@pytest.mark.ros
def test_check_names_missing_ament_prefix(env: dict[str, str]) -> None:
    env.pop("AMENT_PREFIX_PATH", None)
    result = run_cli(["check"], env)
    _assert_fails_cleanly(result, "ament index", "AMENT_PREFIX_PATH")


@pytest.mark.slow
@pytest.mark.ros
def test_check_names_package_missing_from_index(env: dict[str, str], tmp_path: Path) -> None:
    env["AMENT_PREFIX_PATH"] = str(tmp_path)
    result = run_cli(["check"], env)
    _assert_fails_cleanly(result, "ament index", "fence_sorter", "not in the ament index")


@pytest.mark.slow
@pytest.mark.ros
def test_check_names_foreign_rmw(env: dict[str, str]) -> None:
    env["RMW_IMPLEMENTATION"] = "rmw_cyclonedds_cpp"
    result = run_cli(["check"], env)
    _assert_fails_cleanly(result, "rmw", "RMW_IMPLEMENTATION=rmw_cyclonedds_cpp")


@pytest.mark.slow
@pytest.mark.ros
def test_demo_roundtrip(env: dict[str, str]) -> None:
    result = run_cli(["demo-roundtrip", "--timeout", "45"], env)
    assert result.returncode == 0, result.stdout + result.stderr
    # every interface of msg_defs/msg, counted from the source files, not from the code
    msg_dir = Path(__file__).resolve().parents[2] / "msg_defs" / "msg"
    count = len(list(msg_dir.glob("*.msg")))
    assert count >= 6
    assert f"all {count} message types made the round trip" in result.stdout


@pytest.mark.parametrize("args", [["line-sim", "two_units", "--parcels", "2"]])
def test_output_whose_reader_is_gone_ends_quietly_with_141(
    args: list[str], env: dict[str, str]
) -> None:
    """``fence-sorter ... | head``: stdout's reader is gone before the command writes; the
    command ends with 141 (128 + SIGPIPE) and no traceback."""
    read, write = os.pipe()
    os.close(read)
    try:
        proc = subprocess.run(
            [venv_executable("fence-sorter"), *args],
            stdout=write,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            timeout=300,
        )
    finally:
        os.close(write)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""
